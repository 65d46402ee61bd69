// The warp pass: one full-screen triangle; each output pixel samples the cube map along its
// sampling vector V, taken from the analytic projection (mode 0) or from the float normal map
// (mode 1, textureLoad so it binds where Rgba32Float cannot be filtered), then the tile
// screen's f lowers its saturation (seed 000, Figure 5). Prepended: projections.wgsl and
// fullscreen.wgsl. The CPU
// twin is the reference renderer, src/render/mod.rs.

struct Settings {
    // mode, has f map, unused, unused
    head: vec4<u32>,
}

@group(0) @binding(0) var<uniform> pr: Projection;
@group(0) @binding(1) var<uniform> settings: Settings;
@group(0) @binding(2) var cube: texture_cube<f32>;
@group(0) @binding(3) var cube_sampler: sampler;
@group(0) @binding(4) var normals: texture_2d<f32>;
@group(0) @binding(5) var f_map: texture_2d<f32>;

@fragment
fn fs_main(@builtin(position) pos: vec4<f32>) -> @location(0) vec4<f32> {
    // pos.xy is the pixel centre, (i + ½, j + ½), as the CPU path counts.
    let texel = vec2<i32>(pos.xy);
    var v: vec4<f32>;
    if settings.head.x == 0u {
        let s = 2.0 * pos.x / f32(pr.head.z) - 1.0;
        let t = 1.0 - 2.0 * pos.y / f32(pr.head.w);
        v = view_direction(pr, s, t);
    } else {
        v = textureLoad(normals, texel, 0);
    }
    if v.w < 0.5 {
        return vec4<f32>(0.0, 0.0, 0.0, 0.0);
    }
    var c = textureSampleLevel(cube, cube_sampler, v.xyz, 0.0);
    if settings.head.y == 1u {
        let f = clamp(textureLoad(f_map, texel, 0).x, 0.0, 1.0);
        let y = dot(c.rgb, vec3<f32>(0.2126, 0.7152, 0.0722));
        c = vec4<f32>(vec3<f32>(y) + (c.rgb - vec3<f32>(y)) * f, c.a);
    }
    return c;
}
