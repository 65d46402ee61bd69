// What the two scene passes share (the cube-map pass, scene.wgsl, and piecewise perspective,
// ppp.wgsl): a mesh vertex, world position and colour, taken to clip space by the pass's
// matrix, and the flat shading both use, lit from the triangle's own plane as the CPU twin
// lights it (src/scene/raycast.rs). Prepended to scene.wgsl and ppp.wgsl.

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) color: vec4<f32>,
}

fn mesh_vertex(clip: mat4x4<f32>, position: vec3<f32>, color: vec4<f32>) -> VertexOut {
    var out: VertexOut;
    out.clip = clip * vec4<f32>(position, 1.0);
    out.world = position;
    out.color = color;
    return out;
}

// The colour of a fragment of a flat triangle, lit by a sun in direction `sun` (unit, world).
fn flat_shade(in: VertexOut, sun: vec3<f32>) -> vec4<f32> {
    let n = normalize(cross(dpdx(in.world), dpdy(in.world)));
    let light = 0.45 + 0.55 * abs(dot(n, sun));
    return vec4<f32>(in.color.rgb * light, 1.0);
}
