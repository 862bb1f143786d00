//! A fast, stable 64-bit hash over published pixels (`frames_hash` in `handeye sim --json`),
//! for checking that two runs published bit-identical frames. Not cryptographic.

use handeye_vision::rng::mix64;

/// Hash of one buffer: 8 bytes at a time through a multiply-xorshift, then the tail.
pub fn hash_bytes(bytes: &[u8]) -> u64 {
    const K: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut h: u64 = 0x243F_6A88_85A3_08D3 ^ (bytes.len() as u64).wrapping_mul(K);
    let mut chunks = bytes.chunks_exact(8);
    for c in &mut chunks {
        let w = u64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]);
        h = (h ^ w).wrapping_mul(K).rotate_left(29);
    }
    let mut tail = [0u8; 8];
    tail[..chunks.remainder().len()].copy_from_slice(chunks.remainder());
    h = (h ^ u64::from_le_bytes(tail)).wrapping_mul(K);
    mix64(h)
}

/// Running hash over a sequence of frames: order matters, every pixel counts.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FramesHash {
    pub value: u64,
    pub frames: u64,
}

impl FramesHash {
    /// Folds in one frame and returns that frame's own hash.
    pub fn add(&mut self, frame: &[u8]) -> u64 {
        let h = hash_bytes(frame);
        self.value = mix64(self.value ^ h.wrapping_add(self.frames));
        self.frames += 1;
        h
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn any_changed_byte_or_order_changes_the_hash() {
        let a: Vec<u8> = (0..1000u32).map(|i| (i * 7 % 251) as u8).collect();
        let base = hash_bytes(&a);
        for pos in [0, 7, 8, 500, 999] {
            let mut b = a.clone();
            b[pos] ^= 1;
            assert_ne!(hash_bytes(&b), base, "flip at {pos}");
        }
        assert_ne!(hash_bytes(&a[..999]), base, "length counts");
        let (mut x, mut y) = (FramesHash::default(), FramesHash::default());
        x.add(&a[..10]);
        x.add(&a[10..20]);
        y.add(&a[10..20]);
        y.add(&a[..10]);
        assert_ne!(x, y, "frame order counts");
    }
}
