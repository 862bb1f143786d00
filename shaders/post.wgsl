// Camera optics, applied to each rendered view when its blur is on: a Gaussian blur of
// radius `params.y` pixels. (Sensor noise is added on the CPU while the frame is copied out:
// a per-pixel hash and Gaussian here cost ~12 ms per stereo frame on lavapipe.)

struct Post {
    // x: blur sigma (px), y: blur radius (px).
    params: vec4<f32>,
    // x: view index (array layer).
    layer: vec4<u32>,
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

@fragment
fn fs_main(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let layer = i32(post.layer.x);
    let p = vec2<i32>(floor(frag.xy));
    let size = vec2<i32>(textureDimensions(scene));
    let sigma = post.params.x;
    if (sigma <= 0.0) {
        return vec4<f32>(textureLoad(scene, p, layer, 0).r, 0.0, 0.0, 1.0);
    }
    let r = i32(post.params.y);
    var value = 0.0;
    var total = 0.0;
    for (var dy = -r; dy <= r; dy++) {
        for (var dx = -r; dx <= r; dx++) {
            let w = exp(-f32(dx * dx + dy * dy) / (2.0 * sigma * sigma));
            let q = clamp(p + vec2<i32>(dx, dy), vec2<i32>(0), size - vec2<i32>(1));
            value += w * textureLoad(scene, q, layer, 0).r;
            total += w;
        }
    }
    return vec4<f32>(value / total, 0.0, 0.0, 1.0);
}
