// Radial blur (seed 000, Figure 7): each pixel averages samples along the line towards the
// image centre, the blur growing with the distance from it, as speed looks from a vehicle. CPU
// twin, tap for tap: src/render/blur.rs. Prepended: fullscreen.wgsl.

struct Blur {
    // strength (fraction of the distance to the centre covered), samples, width, height
    params: vec4<f32>,
}

@group(0) @binding(0) var<uniform> blur: Blur;
@group(0) @binding(1) var image: texture_2d<f32>;
@group(0) @binding(2) var image_sampler: sampler;

@fragment
fn fs_main(@builtin(position) pos: vec4<f32>) -> @location(0) vec4<f32> {
    let size = blur.params.zw;
    let uv = pos.xy / size;
    let towards = vec2<f32>(0.5, 0.5) - uv;
    let n = max(i32(blur.params.y), 1);
    var sum = vec4<f32>(0.0);
    for (var k = 0; k < n; k = k + 1) {
        let along = blur.params.x * f32(k) / f32(n);
        sum = sum + textureSampleLevel(image, image_sampler, uv + towards * along, 0.0);
    }
    return sum / f32(n);
}
