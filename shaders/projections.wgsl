// δP of every projection and the view transform: the WGSL twins of the projections registered
// in src/projection/mod.rs (one file each beside it) and of View::direction, formula for formula
// (f32 here, f64 there). `Projection` mirrors
// gpu::warp::ProjectionUniform; `kind` and `radial` as in projection::ShaderForm.

struct Projection {
    // kind, radial, output width, output height
    head: vec4<u32>,
    // the formula's constants, as the Rust struct orders them
    p: vec4<f32>,
    // the turn applied after the formula (columns; identity but for the domemaster)
    turn0: vec4<f32>,
    turn1: vec4<f32>,
    turn2: vec4<f32>,
    // the view's orientation C (columns)
    c0: vec4<f32>,
    c1: vec4<f32>,
    c2: vec4<f32>,
    // off-axis vector O in xyz, zoom in w
    offaxis_zoom: vec4<f32>,
}

const PI: f32 = 3.14159265358979;

// A direction and whether there is one (w = 1) or the position is outside the domain (w = 0).
fn none() -> vec4<f32> {
    return vec4<f32>(0.0, 0.0, 0.0, 0.0);
}

fn flat_forward(p: vec4<f32>, s: f32, t: f32) -> vec4<f32> {
    return vec4<f32>(normalize(vec3<f32>(p.x + p.y * s, p.z + p.w * t, -1.0)), 1.0);
}

fn cylindrical_forward(p: vec4<f32>, s: f32, t: f32) -> vec4<f32> {
    let lon = s * p.x;
    if abs(lon) > PI {
        return none();
    }
    return vec4<f32>(normalize(vec3<f32>(sin(lon), t * p.y, -cos(lon))), 1.0);
}

fn cylindrical_vertical_forward(p: vec4<f32>, s: f32, t: f32) -> vec4<f32> {
    let el = t * p.y;
    if abs(el) > PI {
        return none();
    }
    return vec4<f32>(normalize(vec3<f32>(s * p.x, sin(el), -cos(el))), 1.0);
}

fn equirect_forward(p: vec4<f32>, s: f32, t: f32) -> vec4<f32> {
    let lon = s * p.x;
    let lat = t * p.y;
    if abs(lon) > PI || abs(lat) > PI / 2.0 {
        return none();
    }
    return vec4<f32>(cos(lat) * sin(lon), sin(lat), -cos(lat) * cos(lon), 1.0);
}

// R⁻¹(r) of the fisheye family, or a negative number where no angle reaches r.
fn radial_theta(radial: u32, r: f32) -> f32 {
    switch radial {
        case 0u: {
            if r > PI { return -1.0; }
            return r;
        }
        case 1u: {
            if r > 2.0 { return -1.0; }
            return 2.0 * asin(r / 2.0);
        }
        case 2u: {
            return 2.0 * atan(r / 2.0);
        }
        default: {
            if r > 1.0 { return -1.0; }
            return asin(r);
        }
    }
}

fn fisheye_forward(pr: Projection, s: f32, t: f32) -> vec4<f32> {
    let px = s * pr.p.x;
    let py = t * pr.p.y;
    let r = sqrt(px * px + py * py);
    let theta = radial_theta(pr.head.y, r);
    if theta < 0.0 || theta > pr.p.z {
        return none();
    }
    var d = vec3<f32>(0.0, 0.0, -1.0);
    if r > 0.0 {
        d = vec3<f32>(sin(theta) * px / r, sin(theta) * py / r, -cos(theta));
    }
    let turn = mat3x3<f32>(pr.turn0.xyz, pr.turn1.xyz, pr.turn2.xyz);
    return vec4<f32>(turn * d, 1.0);
}

fn delta_p(pr: Projection, s: f32, t: f32) -> vec4<f32> {
    switch pr.head.x {
        case 0u: { return flat_forward(pr.p, s, t); }
        case 1u: { return cylindrical_forward(pr.p, s, t); }
        case 2u: { return cylindrical_vertical_forward(pr.p, s, t); }
        case 3u: { return equirect_forward(pr.p, s, t); }
        default: { return fisheye_forward(pr, s, t); }
    }
}

// View::direction: V = normalize(C·δP(s·zoom, t·zoom) − O).
fn view_direction(pr: Projection, s: f32, t: f32) -> vec4<f32> {
    let zoom = pr.offaxis_zoom.w;
    let d = delta_p(pr, s * zoom, t * zoom);
    if d.w < 0.5 {
        return none();
    }
    let c = mat3x3<f32>(pr.c0.xyz, pr.c1.xyz, pr.c2.xyz);
    return vec4<f32>(normalize(c * d.xyz - pr.offaxis_zoom.xyz), 1.0);
}
