// The cube-map pass: a scene drawn into one cube face per render pass (the face's matrix maps
// the face's (sc, −tc, depth, |ma|) to clip space, so the face texture reads like the CPU's
// cube table), flat shaded from the triangle's own plane. The CPU twin, for machines without an
// adapter, ray-casts the same faces with the same shading: src/scene/raycast.rs.

struct Face {
    clip: mat4x4<f32>,
    // sun direction (unit, world) in xyz
    sun: vec4<f32>,
}

@group(0) @binding(0) var<uniform> face: Face;

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) color: vec4<f32>,
}

@vertex
fn vs_main(@location(0) position: vec3<f32>, @location(1) color: vec4<f32>) -> VertexOut {
    var out: VertexOut;
    out.clip = face.clip * vec4<f32>(position, 1.0);
    out.world = position;
    out.color = color;
    return out;
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    let n = normalize(cross(dpdx(in.world), dpdy(in.world)));
    let light = 0.45 + 0.55 * abs(dot(n, face.sun.xyz));
    return vec4<f32>(in.color.rgb * light, 1.0);
}
