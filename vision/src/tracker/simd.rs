//! Four f32 lanes for the fit's per-point loops: SSE2 on x86_64 (part of its baseline, so no
//! runtime detection), plain arrays elsewhere. Each operation is the lane-wise IEEE operation
//! the scalar code would do, in the same order, so results are identical on both.

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;

/// Four f32 lanes. A mask is a value whose lanes are all-ones or all-zeros bit patterns.
#[derive(Clone, Copy, Debug)]
pub(crate) struct F32x4(#[cfg(target_arch = "x86_64")] __m128, #[cfg(not(target_arch = "x86_64"))] [f32; 4]);

// SAFETY (for every `unsafe` block in this impl on x86_64): SSE2 is part of the x86_64
// baseline, and the loads and stores go through slices of at least four elements.
impl F32x4 {
    #[inline(always)]
    pub fn splat(v: f32) -> Self {
        #[cfg(target_arch = "x86_64")]
        return Self(unsafe { _mm_set1_ps(v) });
        #[cfg(not(target_arch = "x86_64"))]
        return Self([v; 4]);
    }

    /// Lanes `s[i..i + 4]`.
    #[cfg(test)]
    pub fn load(s: &[f32], i: usize) -> Self {
        let s = &s[i..i + 4];
        #[cfg(target_arch = "x86_64")]
        return Self(unsafe { _mm_loadu_ps(s.as_ptr()) });
        #[cfg(not(target_arch = "x86_64"))]
        return Self([s[0], s[1], s[2], s[3]]);
    }

    /// Lanes `p[0..4]`.
    ///
    /// # Safety
    /// `p` points to four readable f32.
    #[inline(always)]
    pub unsafe fn load_ptr(p: *const f32) -> Self {
        #[cfg(target_arch = "x86_64")]
        return Self(unsafe { _mm_loadu_ps(p) });
        #[cfg(not(target_arch = "x86_64"))]
        return Self(unsafe { [*p, *p.add(1), *p.add(2), *p.add(3)] });
    }

    /// Writes the lanes to `p[0..4]`.
    ///
    /// # Safety
    /// `p` points to four writable f32.
    #[inline(always)]
    pub unsafe fn store_ptr(self, p: *mut f32) {
        #[cfg(target_arch = "x86_64")]
        unsafe {
            _mm_storeu_ps(p, self.0)
        };
        #[cfg(not(target_arch = "x86_64"))]
        unsafe {
            std::ptr::copy_nonoverlapping(self.0.as_ptr(), p, 4)
        };
    }

    /// Writes the lanes to `s[i..i + 4]`.
    #[cfg(test)]
    pub fn store(self, s: &mut [f32], i: usize) {
        let s = &mut s[i..i + 4];
        #[cfg(target_arch = "x86_64")]
        unsafe {
            _mm_storeu_ps(s.as_mut_ptr(), self.0)
        };
        #[cfg(not(target_arch = "x86_64"))]
        s.copy_from_slice(&self.0);
    }

    #[inline(always)]
    pub fn to_array(self) -> [f32; 4] {
        #[cfg(target_arch = "x86_64")]
        {
            let mut out = [0.0f32; 4];
            unsafe { _mm_storeu_ps(out.as_mut_ptr(), self.0) };
            out
        }
        #[cfg(not(target_arch = "x86_64"))]
        self.0
    }

    /// The lanes of an array.
    #[cfg(test)]
    #[inline(always)]
    pub fn load_array(v: [f32; 4]) -> Self {
        #[cfg(target_arch = "x86_64")]
        return Self(unsafe { _mm_loadu_ps(v.as_ptr()) });
        #[cfg(not(target_arch = "x86_64"))]
        return Self(v);
    }

    /// Lanes converted from i32 (exact below 2^24).
    #[cfg(test)]
    #[inline(always)]
    pub fn from_i32(v: [i32; 4]) -> Self {
        #[cfg(target_arch = "x86_64")]
        return Self(unsafe { _mm_cvtepi32_ps(_mm_loadu_si128(v.as_ptr() as *const __m128i)) });
        #[cfg(not(target_arch = "x86_64"))]
        return Self(v.map(|x| x as f32));
    }

    /// Lanes truncated towards zero to i32, for values within i32's range.
    #[inline(always)]
    pub fn to_i32_array(self) -> [i32; 4] {
        #[cfg(target_arch = "x86_64")]
        {
            let mut out = [0i32; 4];
            unsafe { _mm_storeu_si128(out.as_mut_ptr() as *mut __m128i, _mm_cvttps_epi32(self.0)) };
            out
        }
        #[cfg(not(target_arch = "x86_64"))]
        std::array::from_fn(|l| self.0[l] as i32)
    }

    #[inline(always)]
    pub fn add(self, o: Self) -> Self {
        #[cfg(target_arch = "x86_64")]
        return Self(unsafe { _mm_add_ps(self.0, o.0) });
        #[cfg(not(target_arch = "x86_64"))]
        return Self(std::array::from_fn(|l| self.0[l] + o.0[l]));
    }

    #[inline(always)]
    pub fn sub(self, o: Self) -> Self {
        #[cfg(target_arch = "x86_64")]
        return Self(unsafe { _mm_sub_ps(self.0, o.0) });
        #[cfg(not(target_arch = "x86_64"))]
        return Self(std::array::from_fn(|l| self.0[l] - o.0[l]));
    }

    #[inline(always)]
    pub fn mul(self, o: Self) -> Self {
        #[cfg(target_arch = "x86_64")]
        return Self(unsafe { _mm_mul_ps(self.0, o.0) });
        #[cfg(not(target_arch = "x86_64"))]
        return Self(std::array::from_fn(|l| self.0[l] * o.0[l]));
    }

    #[inline(always)]
    pub fn div(self, o: Self) -> Self {
        #[cfg(target_arch = "x86_64")]
        return Self(unsafe { _mm_div_ps(self.0, o.0) });
        #[cfg(not(target_arch = "x86_64"))]
        return Self(std::array::from_fn(|l| self.0[l] / o.0[l]));
    }

    /// Lane-wise maximum, for operands that are not NaN (as `f32::max` then).
    #[inline(always)]
    pub fn max(self, o: Self) -> Self {
        #[cfg(target_arch = "x86_64")]
        return Self(unsafe { _mm_max_ps(self.0, o.0) });
        #[cfg(not(target_arch = "x86_64"))]
        return Self(std::array::from_fn(|l| self.0[l].max(o.0[l])));
    }

    /// Lane-wise minimum, for operands that are not NaN (as `f32::min` then).
    #[inline(always)]
    pub fn min(self, o: Self) -> Self {
        #[cfg(target_arch = "x86_64")]
        return Self(unsafe { _mm_min_ps(self.0, o.0) });
        #[cfg(not(target_arch = "x86_64"))]
        return Self(std::array::from_fn(|l| self.0[l].min(o.0[l])));
    }

    #[inline(always)]
    pub fn abs(self) -> Self {
        #[cfg(target_arch = "x86_64")]
        return Self(unsafe { _mm_andnot_ps(_mm_set1_ps(-0.0), self.0) });
        #[cfg(not(target_arch = "x86_64"))]
        return Self(std::array::from_fn(|l| self.0[l].abs()));
    }

    /// Mask of the lanes where `self < o`.
    #[inline(always)]
    pub fn lt(self, o: Self) -> Self {
        #[cfg(target_arch = "x86_64")]
        return Self(unsafe { _mm_cmplt_ps(self.0, o.0) });
        #[cfg(not(target_arch = "x86_64"))]
        return Self(std::array::from_fn(|l| mask_lane(self.0[l] < o.0[l])));
    }

    /// Mask of the lanes where `self <= o`.
    #[inline(always)]
    pub fn le(self, o: Self) -> Self {
        #[cfg(target_arch = "x86_64")]
        return Self(unsafe { _mm_cmple_ps(self.0, o.0) });
        #[cfg(not(target_arch = "x86_64"))]
        return Self(std::array::from_fn(|l| mask_lane(self.0[l] <= o.0[l])));
    }

    /// `self` where `mask` is set, else +0.
    #[inline(always)]
    pub fn and(self, mask: Self) -> Self {
        #[cfg(target_arch = "x86_64")]
        return Self(unsafe { _mm_and_ps(self.0, mask.0) });
        #[cfg(not(target_arch = "x86_64"))]
        return Self(std::array::from_fn(|l| f32::from_bits(self.0[l].to_bits() & mask.0[l].to_bits())));
    }

    /// `a` where `self` (a mask) is set, else `b`.
    #[inline(always)]
    pub fn select(self, a: Self, b: Self) -> Self {
        #[cfg(target_arch = "x86_64")]
        return Self(unsafe { _mm_or_ps(_mm_and_ps(self.0, a.0), _mm_andnot_ps(self.0, b.0)) });
        #[cfg(not(target_arch = "x86_64"))]
        return Self(std::array::from_fn(|l| {
            let m = self.0[l].to_bits();
            f32::from_bits((a.0[l].to_bits() & m) | (b.0[l].to_bits() & !m))
        }));
    }

    /// Bit `l` set where lane `l` of a mask is set.
    #[inline(always)]
    pub fn mask_bits(self) -> u32 {
        #[cfg(target_arch = "x86_64")]
        return unsafe { _mm_movemask_ps(self.0) } as u32;
        #[cfg(not(target_arch = "x86_64"))]
        return (0..4).map(|l| ((self.0[l].to_bits() >> 31) << l)).sum();
    }
}

#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn mask_lane(set: bool) -> f32 {
    f32::from_bits(if set { u32::MAX } else { 0 })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lanes_do_what_the_scalar_operations_do() {
        let a = [1.5f32, -2.0, f32::INFINITY, 0.25];
        let b = [0.5f32, -3.0, 7.0, 0.25];
        let (va, vb) = (F32x4::load(&a, 0), F32x4::load(&b, 0));
        let each = |f: &dyn Fn(f32, f32) -> f32| -> [f32; 4] { std::array::from_fn(|l| f(a[l], b[l])) };
        assert_eq!(va.add(vb).to_array(), each(&|x, y| x + y));
        assert_eq!(va.sub(vb).to_array(), each(&|x, y| x - y));
        assert_eq!(va.mul(vb).to_array(), each(&|x, y| x * y));
        assert_eq!(va.div(vb).to_array(), each(&|x, y| x / y));
        assert_eq!(va.max(vb).to_array(), each(&|x, y| x.max(y)));
        assert_eq!(va.min(vb).to_array(), each(&|x, y| x.min(y)));
        assert_eq!(F32x4::from_i32([-3, 0, 7, 1 << 20]).to_array(), [-3.0, 0.0, 7.0, 1048576.0]);
        assert_eq!(va.abs().to_array(), [1.5, 2.0, f32::INFINITY, 0.25]);
        assert_eq!(va.lt(vb).mask_bits(), 0b0000);
        assert_eq!(vb.lt(va).mask_bits(), 0b0111);
        assert_eq!(va.le(vb).mask_bits(), 0b1000);
        let m = vb.lt(va);
        assert_eq!(m.select(vb, va).to_array(), [0.5, -3.0, 7.0, 0.25]);
        assert_eq!(va.lt(vb).select(vb, va).to_array(), a);
        assert_eq!(va.and(m).to_array(), [1.5, -2.0, f32::INFINITY, 0.0]);
        let mut out = [0.0f32; 6];
        va.store(&mut out, 2);
        assert_eq!(out, [0.0, 0.0, 1.5, -2.0, f32::INFINITY, 0.25]);
        assert_eq!(F32x4::splat(3.0).to_array(), [3.0; 4]);
        assert_eq!(F32x4::load(&[0.0, 2.9, -2.9, 254.99], 0).to_i32_array(), [0, 2, -2, 254]);
    }
}
