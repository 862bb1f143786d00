// Camera optics and sensor, applied to each rendered view: Gaussian blur (optional), then
// additive Gaussian noise from a counter-based hash of (pixel, view, frame seed), so every
// frame's noise is reproducible bit for bit and no random state lives on the GPU.

struct Post {
    // x: blur sigma (px, 0 = none), y: noise sigma (grey levels / 255), z: blur radius (px).
    params: vec4<f32>,
    // x: frame seed, y: view index.
    seed: vec4<u32>,
};

@group(0) @binding(0) var<uniform> post: Post;
@group(0) @binding(1) var scene: texture_2d_array<f32>;

// A full-screen triangle.
@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let x = f32((i << 1u) & 2u) * 2.0 - 1.0;
    let y = f32(i & 2u) * 2.0 - 1.0;
    return vec4<f32>(x, y, 0.0, 1.0);
}

// PCG-style integer hash.
fn hash(v: u32) -> u32 {
    let state = v * 747796405u + 2891336453u;
    let word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

// Uniform in (0, 1).
fn unit(h: u32) -> f32 {
    return (f32(h >> 8u) + 0.5) / 16777216.0;
}

@fragment
fn fs_main(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let layer = i32(post.seed.y);
    let p = vec2<i32>(floor(frag.xy));
    let size = vec2<i32>(textureDimensions(scene));
    var value = 0.0;
    let sigma = post.params.x;
    if (sigma > 0.0) {
        let r = i32(post.params.z);
        var total = 0.0;
        for (var dy = -r; dy <= r; dy++) {
            for (var dx = -r; dx <= r; dx++) {
                let w = exp(-f32(dx * dx + dy * dy) / (2.0 * sigma * sigma));
                let q = clamp(p + vec2<i32>(dx, dy), vec2<i32>(0), size - vec2<i32>(1));
                value += w * textureLoad(scene, q, layer, 0).r;
                total += w;
            }
        }
        value /= total;
    } else {
        value = textureLoad(scene, p, layer, 0).r;
    }
    if (post.params.y > 0.0) {
        let key = hash(u32(p.x) ^ hash(u32(p.y) ^ hash(post.seed.x ^ (post.seed.y * 0x9e3779b9u))));
        let u1 = unit(key);
        let u2 = unit(hash(key));
        let gauss = sqrt(-2.0 * log(u1)) * cos(6.2831853 * u2);
        value += gauss * post.params.y;
    }
    return vec4<f32>(clamp(value, 0.0, 1.0), 0.0, 0.0, 1.0);
}
