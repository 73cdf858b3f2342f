// LiDAR points splatted over a camera image, projected on the GPU through the full camera model,
// with occlusion by depth-tested splats.
//
// Each instance is one LiDAR point in its sensor frame with its intensity and a packed index:
// bits 0..24 the firing-time bucket, bits 24..32 the LiDAR. `camera_from_lidar[bucket]`
// (computed on the CPU from the trajectory at the bucket's time, the LiDAR and camera
// extrinsics and the image stamp) moves the point into the camera's optical frame; the camera
// model (pinhole, plumb_bob / rational_polynomial radial-tangential, or equidistant fisheye, as
// in src/geometry/camera.rs) gives the pixel. Six vertices per instance make a round splat.
//
// Two passes into an offscreen target with a depth buffer (depth = range / range_max):
//   1. `vs_depth`/`fs_depth` write the depth of every point as a large splat of radius
//      `occlusion_px` and no colour, so near surfaces cover the points behind them;
//   2. `vs_color`/`fs_color` draw each point as a splat of radius `point_size_px`, its depth
//      pulled forward by `depth_tolerance` (relative), with the depth test LessEqual: a point
//      survives only where nothing clearly nearer was splatted.
// The viewport shows image pixels `view_min .. view_min + view_size` (zoom and pan).

struct Uniforms {
    focal: vec2<f32>,
    principal: vec2<f32>,
    image_size: vec2<f32>,
    viewport_size_px: vec2<f32>,
    // k1, k2, p1, p2 | k3, k4, k5, k6 (ROS order); fisheye: k1..k4 in radtan0.
    radtan0: vec4<f32>,
    radtan1: vec4<f32>,
    // 0 pinhole / radial-tangential, 1 equidistant fisheye.
    model: u32,
    // 0 range, 1 intensity, 2 height in the vehicle frame, 3 LiDAR.
    color_mode: u32,
    point_size_px: f32,
    opacity: f32,
    range_min_m: f32,
    range_max_m: f32,
    intensity_max: f32,
    occlusion_px: f32,
    view_min: vec2<f32>,
    view_size: vec2<f32>,
    height_min_m: f32,
    height_max_m: f32,
    depth_tolerance: f32,
    _pad: f32,
    // Per LiDAR: the z row of vehicle_from_lidar (r20, r21, r22, t_z).
    height_rows: array<vec4<f32>, 8>,
};

@group(0) @binding(0) var<uniform> u: Uniforms;
@group(0) @binding(1) var<storage, read> camera_from_lidar: array<mat4x4<f32>>;

struct PointIn {
    @location(0) position_intensity: vec4<f32>,
    @location(1) packed: u32,
};

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) corner: vec2<f32>,
    @location(1) color: vec4<f32>,
};

fn distort(p: vec3<f32>) -> vec2<f32> {
    if (u.model == 1u) {
        let r = length(p.xy);
        if (r < 1e-9) {
            return p.xy / p.z;
        }
        let theta = atan2(r, p.z);
        let t2 = theta * theta;
        let k = u.radtan0;
        let theta_d = theta * (1.0 + t2 * (k.x + t2 * (k.y + t2 * (k.z + t2 * k.w))));
        return p.xy * (theta_d / r);
    }
    let xy = p.xy / p.z;
    let r2 = dot(xy, xy);
    let a = u.radtan0;
    let b = u.radtan1;
    let radial = (1.0 + r2 * (a.x + r2 * (a.y + r2 * b.x))) / (1.0 + r2 * (b.y + r2 * (b.z + r2 * b.w)));
    let x = xy.x;
    let y = xy.y;
    return vec2<f32>(
        x * radial + 2.0 * a.z * x * y + a.w * (r2 + 2.0 * x * x),
        y * radial + a.z * (r2 + 2.0 * y * y) + 2.0 * a.w * x * y,
    );
}

// Turbo-like colour map, t in [0, 1].
fn colormap(t_in: f32) -> vec3<f32> {
    let t = clamp(t_in, 0.0, 1.0);
    let r = 0.13572138 + t * (4.6153926 + t * (-42.66032258 + t * (132.13108234 + t * (-152.94239396 + t * 59.28637943))));
    let g = 0.09140261 + t * (2.19418839 + t * (4.84296658 + t * (-14.18503333 + t * (4.27729857 + t * 2.82956604))));
    let b = 0.1066733 + t * (12.64194608 + t * (-60.58204836 + t * (110.36276771 + t * (-89.90310912 + t * 27.34824973))));
    return clamp(vec3<f32>(r, g, b), vec3<f32>(0.0), vec3<f32>(1.0));
}

// One colour per LiDAR.
const PALETTE = array<vec3<f32>, 8>(
    vec3<f32>(1.0, 0.35, 0.2), vec3<f32>(0.2, 0.8, 1.0), vec3<f32>(0.45, 1.0, 0.3),
    vec3<f32>(1.0, 0.85, 0.15), vec3<f32>(0.85, 0.4, 1.0), vec3<f32>(1.0, 1.0, 1.0),
    vec3<f32>(1.0, 0.5, 0.7), vec3<f32>(0.5, 0.6, 1.0),
);

const CORNERS = array<vec2<f32>, 6>(
    vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, -1.0), vec2<f32>(1.0, 1.0),
    vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, 1.0), vec2<f32>(-1.0, 1.0),
);

// A projected point: clip-space centre (w = 0 when culled) and its range.
struct Projected {
    ndc: vec2<f32>,
    range: f32,
    visible: bool,
    p_lidar: vec3<f32>,
};

fn project(point: PointIn) -> Projected {
    var out: Projected;
    out.visible = false;
    out.p_lidar = point.position_intensity.xyz;
    let bucket = point.packed & 0xFFFFFFu;
    if (bucket >= arrayLength(&camera_from_lidar)) {
        return out;
    }
    let p = (camera_from_lidar[bucket] * vec4<f32>(point.position_intensity.xyz, 1.0)).xyz;
    let range = length(p);
    out.range = range;
    if (p.z <= 0.05 || range < u.range_min_m || range > u.range_max_m) {
        return out;
    }
    // Beyond ~100° off-axis a pinhole/radial model folds over: cull.
    if (u.model == 0u && length(p.xy) > 8.0 * p.z) {
        return out;
    }
    let pixel = u.focal * distort(p) + u.principal;
    if (pixel.x < -0.5 || pixel.y < -0.5 || pixel.x > u.image_size.x - 0.5 || pixel.y > u.image_size.y - 0.5) {
        return out;
    }
    out.ndc = vec2<f32>(
        2.0 * (pixel.x + 0.5 - u.view_min.x) / u.view_size.x - 1.0,
        1.0 - 2.0 * (pixel.y + 0.5 - u.view_min.y) / u.view_size.y,
    );
    out.visible = true;
    return out;
}

fn splat(pr: Projected, corner: vec2<f32>, radius_px: f32, depth: f32) -> vec4<f32> {
    // NDC spans 2 across the viewport: a radius of r pixels is 2r / size in NDC.
    let offset = corner * 2.0 * radius_px / u.viewport_size_px;
    return vec4<f32>(pr.ndc + offset, clamp(depth, 0.0, 1.0), 1.0);
}

fn culled() -> VertexOut {
    var out: VertexOut;
    out.clip = vec4<f32>(0.0, 0.0, 2.0, 1.0);
    out.corner = vec2<f32>(0.0);
    out.color = vec4<f32>(0.0);
    return out;
}

@vertex
fn vs_depth(@builtin(vertex_index) vi: u32, point: PointIn) -> VertexOut {
    let pr = project(point);
    if (!pr.visible) {
        return culled();
    }
    var out: VertexOut;
    out.corner = CORNERS[vi % 6u];
    out.clip = splat(pr, out.corner, u.occlusion_px, pr.range / (u.range_max_m * 1.001));
    out.color = vec4<f32>(0.0);
    return out;
}

// Depth only: the pipeline's colour write mask is empty.
@fragment
fn fs_depth(in: VertexOut) -> @location(0) vec4<f32> {
    if (dot(in.corner, in.corner) > 1.0) {
        discard;
    }
    return vec4<f32>(0.0);
}

@vertex
fn vs_color(@builtin(vertex_index) vi: u32, point: PointIn) -> VertexOut {
    let pr = project(point);
    if (!pr.visible) {
        return culled();
    }
    var out: VertexOut;
    out.corner = CORNERS[vi % 6u];
    let depth = pr.range * (1.0 - u.depth_tolerance) / (u.range_max_m * 1.001);
    out.clip = splat(pr, out.corner, u.point_size_px, depth);
    let lidar = min(point.packed >> 24u, 7u);
    var rgb: vec3<f32>;
    if (u.color_mode == 1u) {
        rgb = colormap(point.position_intensity.w / max(u.intensity_max, 1e-6));
    } else if (u.color_mode == 2u) {
        let row = u.height_rows[lidar];
        let height = dot(row.xyz, pr.p_lidar) + row.w;
        rgb = colormap((height - u.height_min_m) / max(u.height_max_m - u.height_min_m, 1e-6));
    } else if (u.color_mode == 3u) {
        rgb = PALETTE[lidar];
    } else {
        rgb = colormap((pr.range - u.range_min_m) / max(u.range_max_m - u.range_min_m, 1e-6));
    }
    out.color = vec4<f32>(rgb, u.opacity);
    return out;
}

@fragment
fn fs_color(in: VertexOut) -> @location(0) vec4<f32> {
    if (dot(in.corner, in.corner) > 1.0) {
        discard;
    }
    // Premultiplied alpha, as egui's render target expects.
    return vec4<f32>(in.color.rgb * in.color.a, in.color.a);
}
