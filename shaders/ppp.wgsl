// Piecewise perspective projection (seed 003): the scene drawn straight into the output, one
// perspective piece at a time. Each piece's matrix takes a world point to the output's clip
// space through the piece's own pinhole camera (the inverse of its linear pixel → direction
// map, src/scene/ppp.rs); the scissor rectangle clips it to its cell, and a cell cut into two
// triangles keeps, per pixel, the half on its side of the diagonal. Shading is the cube-map
// pass's (shaders/scene.wgsl). The CPU twin ray-casts each pixel along the piece's direction:
// `RayCaster::picture` with `Pieces::ray` (src/scene/raycast.rs). Prepended: mesh.wgsl.

struct Piece {
    clip: mat4x4<f32>,
    // sun direction (unit, world) in xyz
    sun: vec4<f32>,
    // the cell's diagonal, doubled pixel coordinates: x0, y0, x1, y1
    diagonal: vec4<i32>,
    // x: 0 the whole cell, 1 strictly above the diagonal, 2 on it and below
    half: vec4<u32>,
}

@group(0) @binding(0) var<uniform> piece: Piece;

@vertex
fn vs_main(@location(0) position: vec3<f32>, @location(1) color: vec4<f32>) -> VertexOut {
    return mesh_vertex(piece.clip, position, color);
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    // Pixel centres are at i + 0.5: doubled, they are odd integers, exactly.
    let p = vec2<i32>(in.clip.xy * 2.0);
    let g = piece.diagonal;
    let side = (p.x - g.x) * (g.w - g.y) - (p.y - g.y) * (g.z - g.x);
    if (piece.half.x == 1u && side <= 0) || (piece.half.x == 2u && side > 0) {
        discard;
    }
    return flat_shade(in, piece.sun.xyz);
}
