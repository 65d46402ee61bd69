// The cube-map pass: a scene drawn into one cube face per render pass (the face's matrix maps
// the face's (sc, −tc, depth, |ma|) to clip space, so the face texture reads like the CPU's
// cube table), flat shaded from the triangle's own plane. The CPU twin, for machines without an
// adapter, ray-casts the same faces with the same shading: src/scene/raycast.rs. Prepended:
// mesh.wgsl.

struct Face {
    clip: mat4x4<f32>,
    // sun direction (unit, world) in xyz
    sun: vec4<f32>,
    // the face's axes sc, −tc and ma (world, unit) in xyz: see fs_sky
    axis0: vec4<f32>,
    axis1: vec4<f32>,
    axis2: vec4<f32>,
}

@group(0) @binding(0) var<uniform> face: Face;

@vertex
fn vs_main(@location(0) position: vec3<f32>, @location(1) color: vec4<f32>) -> VertexOut {
    return mesh_vertex(face.clip, position, color);
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    return flat_shade(in, face.sun.xyz);
}

// Panoramic projective texture mapping (seed 001): instead of its own colours, every surface
// point P shows the panorama's direction P − C, C the panorama's projection centre; where the
// eye sees no surface, the panorama in the ray's own direction (a point at infinity lies in
// that direction from any C). The panorama is the CPU's padded atlas (src/content/atlas.rs)
// and is located in it exactly as `Locate::locate` does (src/content/mod.rs); the CPU twin is
// `RayCaster::cube_projected` in src/scene/raycast.rs.

struct Panorama {
    // centre C (world) in xyz
    centre: vec4<f32>,
    // world → panorama frame (Content::frame: the inverse of the content orientation, and a
    // dome master's turn), by columns
    turn0: vec4<f32>,
    turn1: vec4<f32>,
    turn2: vec4<f32>,
    // kind (0 cube, 1 equirect, 2 cylinder, 3 fisheye), atlas width, atlas height, pad
    head: vec4<u32>,
    // cube: face size; panorama: width, height, hfov (radians), vfov (radians) or H;
    // fisheye: the circle's centre x, y and radius (atlas texels), half its field of view
    p: vec4<f32>,
}

@group(1) @binding(0) var<uniform> pano: Panorama;
@group(1) @binding(1) var atlas: texture_2d<f32>;
@group(1) @binding(2) var atlas_sampler: sampler;

// Atlas texel coordinates of direction d (integers at texel centres) in xy; z = 1 where the
// panorama covers d.
fn pano_locate(world: vec3<f32>) -> vec3<f32> {
    let d = mat3x3<f32>(pano.turn0.xyz, pano.turn1.xyz, pano.turn2.xyz) * world;
    let pad = f32(pano.head.w);
    if pano.head.x == 0u {
        let a = abs(d);
        var face: u32;
        var sc: f32;
        var tc: f32;
        var ma: f32;
        if a.x >= a.y && a.x >= a.z {
            ma = a.x;
            tc = -d.y;
            if d.x >= 0.0 { face = 0u; sc = -d.z; } else { face = 1u; sc = d.z; }
        } else if a.y >= a.z {
            ma = a.y;
            sc = d.x;
            if d.y >= 0.0 { face = 2u; tc = d.z; } else { face = 3u; tc = -d.z; }
        } else {
            ma = a.z;
            tc = -d.y;
            if d.z >= 0.0 { face = 4u; sc = d.x; } else { face = 5u; sc = -d.x; }
        }
        let n = pano.p.x;
        let s = 0.5 * (sc / ma + 1.0);
        let t = 0.5 * (tc / ma + 1.0);
        let y0 = f32(face) * (n + 2.0 * pad);
        return vec3<f32>(s * n - 0.5 + pad, y0 + t * n - 0.5 + pad, 1.0);
    }
    if pano.head.x == 3u {
        let rho = length(d.xy);
        let theta = atan2(rho, -d.z);
        if theta > pano.p.w {
            return vec3<f32>(0.0);
        }
        if rho == 0.0 {
            return vec3<f32>(pano.p.xy, 1.0);
        }
        let k = pano.p.z * theta / (pano.p.w * rho);
        let at = vec2<f32>(pano.p.x + k * d.x, pano.p.y - k * d.y);
        // A full-frame fisheye's circle reaches past the frame, which holds nothing there.
        let far = vec2<f32>(f32(pano.head.y), f32(pano.head.z)) - pad - 0.5;
        if any(at < vec2<f32>(pad - 0.5)) || any(at > far) {
            return vec3<f32>(0.0);
        }
        return vec3<f32>(at, 1.0);
    }
    let u = 0.5 + atan2(d.x, -d.z) / pano.p.z;
    let rho = length(d.xz);
    var v: f32;
    if pano.head.x == 1u {
        v = 0.5 - atan2(d.y, rho) / pano.p.w;
    } else {
        if rho == 0.0 {
            return vec3<f32>(0.0);
        }
        v = 0.5 - d.y / (rho * pano.p.w);
    }
    if u < 0.0 || u > 1.0 || v < 0.0 || v > 1.0 {
        return vec3<f32>(0.0);
    }
    return vec3<f32>(u * pano.p.x - 0.5 + pad, v * pano.p.y - 0.5 + pad, 1.0);
}

// The panorama in direction d; opaque black where it does not reach.
fn pano_sample(d: vec3<f32>) -> vec4<f32> {
    let at = pano_locate(d);
    if at.z < 0.5 {
        return vec4<f32>(0.0, 0.0, 0.0, 1.0);
    }
    let size = vec2<f32>(f32(pano.head.y), f32(pano.head.z));
    let c = textureSampleLevel(atlas, atlas_sampler, (at.xy + 0.5) / size, 0.0);
    return vec4<f32>(c.rgb, 1.0);
}

@fragment
fn fs_projected(in: VertexOut) -> @location(0) vec4<f32> {
    return pano_sample(in.world - pano.centre.xyz);
}

struct SkyOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) ndc: vec2<f32>,
}

// One triangle over the whole face, drawn first, without depth.
@vertex
fn vs_sky(@builtin(vertex_index) i: u32) -> SkyOut {
    let x = f32(i32(i & 1u) * 4 - 1);
    let y = f32(i32(i >> 1u) * 4 - 1);
    var out: SkyOut;
    out.clip = vec4<f32>(x, y, 0.0, 1.0);
    out.ndc = vec2<f32>(x, y);
    return out;
}

// The face's clip x, y are (sc, −tc)/|ma| of the direction (src/gpu/cube.rs, face_matrix), and
// the three axes are orthonormal: the direction is x·sc + y·(−tc) + ma.
@fragment
fn fs_sky(in: SkyOut) -> @location(0) vec4<f32> {
    let d = in.ndc.x * face.axis0.xyz + in.ndc.y * face.axis1.xyz + face.axis2.xyz;
    return pano_sample(d);
}
