// The player's pass (src/gpu/show.rs): a channel's finished picture, already warped and
// blended on the CPU, put on its output pixel for pixel. Values are copied, not filtered or
// converted, so what the projector receives is the CPU renderer's frame bit for bit; a window
// of another size than the picture shows it scaled to fit by nearest pixel, as a preview. CPU
// twin: src/play/headless.rs, which without an adapter writes the picture as it came.
// Prepended: fullscreen.wgsl.

struct Show {
    // The output's size in pixels.
    size: vec2<f32>,
    // 1 shows black instead of the picture (the operator's mute), 0 the picture.
    black: u32,
    _pad: u32,
}

@group(0) @binding(0) var picture: texture_2d<f32>;
@group(0) @binding(1) var<uniform> show: Show;

@fragment
fn fs_main(@builtin(position) pos: vec4<f32>) -> @location(0) vec4<f32> {
    if show.black != 0u {
        return vec4<f32>(0.0, 0.0, 0.0, 1.0);
    }
    let dims = textureDimensions(picture);
    let at = vec2<u32>(floor(pos.xy * vec2<f32>(dims) / show.size));
    let c = textureLoad(picture, min(at, dims - vec2<u32>(1u)), 0);
    return vec4<f32>(c.rgb, 1.0);
}
