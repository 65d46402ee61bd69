// The full-screen triangle of the image passes (warp, blur): vertices (−1, −1), (3, −1) and
// (−1, 3), whose triangle covers the viewport, so the fragment stage runs once per output pixel
// with its centre (i + ½, j + ½) in @builtin(position), as the CPU path counts pixels
// (src/render/mod.rs). Prepended to warp.wgsl and blur.wgsl.

@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let x = f32(i32(i & 1u) * 4 - 1);
    let y = f32(i32(i >> 1u) * 4 - 1);
    return vec4<f32>(x, y, 0.0, 1.0);
}
