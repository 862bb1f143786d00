// The work cell, drawn once per camera. Vertices arrive in the robot frame (the CPU applies
// each body's pose); the per-view uniform holds that camera's clip matrix, derived from the
// same 3x4 projection ground truth uses. Flat Lambertian shading: each face has one normal
// and one albedo, so neighbouring faces differ in brightness and block edges show.

struct View {
    // Robot frame -> wgpu clip space.
    clip_from_robot: mat4x4<f32>,
    // xyz: unit vector towards the light; w: directional intensity.
    light: vec4<f32>,
    // x: ambient light.
    params: vec4<f32>,
};

@group(0) @binding(0) var<uniform> view: View;

struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) shade: f32,
    @location(3) id: u32,
};

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) @interpolate(flat) brightness: f32,
    @location(1) @interpolate(flat) id: u32,
};

@vertex
fn vs_main(v: VertexIn) -> VertexOut {
    var out: VertexOut;
    out.clip = view.clip_from_robot * vec4<f32>(v.position, 1.0);
    let diffuse = max(dot(normalize(v.normal), view.light.xyz), 0.0);
    out.brightness = clamp(v.shade * (view.params.x + view.light.w * diffuse), 0.0, 1.0);
    out.id = v.id;
    return out;
}

// Grey level into an R8Unorm target.
@fragment
fn fs_shade(v: VertexOut) -> @location(0) vec4<f32> {
    return vec4<f32>(v.brightness, 0.0, 0.0, 1.0);
}

// Face id into an R32Uint target (ground truth: which face covers each pixel).
@fragment
fn fs_id(v: VertexOut) -> @location(0) u32 {
    return v.id;
}
