// LiDAR points splatted over a camera image by compute shaders, projected through the full camera
// model, with occlusion by depth-tested splats.
//
// `points` holds five 32-bit words per LiDAR point: x, y, z (sensor frame, f32 bits), intensity
// and a packed index (bits 0..24 the firing-time bucket, bits 24..32 the LiDAR).
// `camera_from_lidar[bucket * rows + row]` (computed on the CPU from the trajectory at the
// bucket's time, the LiDAR and camera extrinsics and the image stamp) moves a point into the
// camera's optical frame; a rolling-shutter camera has `rows` poses per bucket, from the image's
// top edge to its bottom edge, and a point is moved by the middle one first, then by the one of
// the row it fell on (a global shutter has one). The camera model (pinhole, plumb_bob /
// rational_polynomial radial-tangential, or equidistant fisheye, as in src/geometry/camera.rs)
// gives the pixel, and the view (zoom and pan: image pixels `view_min .. view_min + view_size`)
// the pixel of the viewport target.
//
// Points are splatted with atomics instead of rasterised triangles: on software Vulkan
// (lavapipe, what CPU-only laptops run) this is several times faster than one small triangle
// per point. Two passes, one invocation per point:
//   1. `cs_occlusion` (when occlusion is on) writes each point's quantised depth as a disk of
//      radius `occlusion_px` into a quarter-resolution buffer, nearest wins (atomicMax of the
//      inverted depth), so near surfaces cover the points behind them;
//   2. `cs_splat` keeps a point only if nothing clearly nearer (by more than
//      `depth_tolerance`, relative) covers its cell, and writes it as a disk of radius
//      `point_size_px` into the full-resolution buffer: inverted depth in the high 16 bits
//      (nearest wins), its 8-bit colour value and LiDAR index below.
// `overlay_blit.wgsl` turns that buffer into colours in egui's render pass.

struct Uniforms {
    focal: vec2<f32>,
    principal: vec2<f32>,
    image_size: vec2<f32>,
    // Size of the target in pixels (the viewport on screen, physical pixels).
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
    // Number of points.
    count: u32,
    // Per LiDAR: the z row of vehicle_from_lidar (r20, r21, r22, t_z).
    height_rows: array<vec4<f32>, 8>,
    // Camera poses per bucket: 1, or the rows of a rolling shutter.
    rows: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
};

@group(0) @binding(0) var<uniform> u: Uniforms;
@group(0) @binding(1) var<storage, read> camera_from_lidar: array<mat4x4<f32>>;
@group(0) @binding(2) var<storage, read> points: array<u32>;
@group(0) @binding(3) var<storage, read_write> occlusion: array<atomic<u32>>;
@group(0) @binding(4) var<storage, read_write> splats: array<atomic<u32>>;

// Occlusion buffer: one cell per OCCLUSION_CELL × OCCLUSION_CELL target pixels.
const OCCLUSION_CELL: f32 = 4.0;
const GROUP: u32 = 64u;
// Invocations per row of the 2D dispatch grid (65535 workgroups of GROUP).
const ROW: u32 = 4194240u;

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

struct Projected {
    // Position in the target (pixels).
    target_px: vec2<f32>,
    range: f32,
    // Quantised range: 0 (near) .. 65535 (range_max).
    depth_q: u32,
    visible: bool,
    // The point's 8-bit colour value and LiDAR index.
    value: u32,
    lidar: u32,
};

fn project(index: u32) -> Projected {
    var out: Projected;
    out.visible = false;
    let base = index * 5u;
    let p_lidar = vec3<f32>(
        bitcast<f32>(points[base]),
        bitcast<f32>(points[base + 1u]),
        bitcast<f32>(points[base + 2u]),
    );
    let intensity = bitcast<f32>(points[base + 3u]);
    let packed = points[base + 4u];
    let rows = max(u.rows, 1u);
    let first = (packed & 0xFFFFFFu) * rows;
    if (first + rows > arrayLength(&camera_from_lidar)) {
        return out;
    }
    var p = (camera_from_lidar[first + rows / 2u] * vec4<f32>(p_lidar, 1.0)).xyz;
    if (rows > 1u && p.z > 0.05) {
        let y = u.focal.y * distort(p).y + u.principal.y;
        let fraction = clamp((y + 0.5) / u.image_size.y, 0.0, 1.0);
        let row = u32(round(fraction * f32(rows - 1u)));
        p = (camera_from_lidar[first + row] * vec4<f32>(p_lidar, 1.0)).xyz;
    }
    let range = length(p);
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
    out.target_px = (pixel + vec2<f32>(0.5) - u.view_min) / u.view_size * u.viewport_size_px;
    out.range = range;
    out.depth_q = u32(clamp(range / u.range_max_m, 0.0, 1.0) * 65535.0);
    out.lidar = min(packed >> 24u, 7u);
    var t: f32;
    if (u.color_mode == 1u) {
        t = intensity / max(u.intensity_max, 1e-6);
    } else if (u.color_mode == 2u) {
        let row = u.height_rows[out.lidar];
        t = (dot(row.xyz, p_lidar) + row.w - u.height_min_m) / max(u.height_max_m - u.height_min_m, 1e-6);
    } else {
        t = (range - u.range_min_m) / max(u.range_max_m - u.range_min_m, 1e-6);
    }
    out.value = u32(clamp(t, 0.0, 1.0) * 255.0);
    out.visible = true;
    return out;
}

fn point_index(gid: vec3<u32>) -> u32 {
    return gid.y * ROW + gid.x;
}

fn occlusion_size() -> vec2<i32> {
    return vec2<i32>(ceil(u.viewport_size_px / OCCLUSION_CELL));
}

@compute @workgroup_size(64)
fn cs_occlusion(@builtin(global_invocation_id) gid: vec3<u32>) {
    let index = point_index(gid);
    if (index >= u.count) {
        return;
    }
    let pr = project(index);
    if (!pr.visible) {
        return;
    }
    let size = occlusion_size();
    let cell = vec2<i32>(floor(pr.target_px / OCCLUSION_CELL));
    let r = i32(ceil(u.occlusion_px / OCCLUSION_CELL));
    let value = 65536u - pr.depth_q;
    for (var dy = -r; dy <= r; dy++) {
        for (var dx = -r; dx <= r; dx++) {
            let c = cell + vec2<i32>(dx, dy);
            if (c.x >= 0 && c.y >= 0 && c.x < size.x && c.y < size.y) {
                atomicMax(&occlusion[c.y * size.x + c.x], value);
            }
        }
    }
}

@compute @workgroup_size(64)
fn cs_splat(@builtin(global_invocation_id) gid: vec3<u32>) {
    let index = point_index(gid);
    if (index >= u.count) {
        return;
    }
    let pr = project(index);
    if (!pr.visible) {
        return;
    }
    if (u.occlusion_px > 0.0) {
        let size = occlusion_size();
        let cell = clamp(vec2<i32>(floor(pr.target_px / OCCLUSION_CELL)), vec2<i32>(0), size - vec2<i32>(1));
        let nearest = atomicLoad(&occlusion[cell.y * size.x + cell.x]);
        if (nearest > 0u) {
            let nearest_q = f32(65536u - nearest);
            if (f32(pr.depth_q) * (1.0 - u.depth_tolerance) > nearest_q) {
                return;
            }
        }
    }
    let w = i32(u.viewport_size_px.x);
    let h = i32(u.viewport_size_px.y);
    let center = vec2<i32>(floor(pr.target_px));
    let s = u.point_size_px;
    let r = i32(ceil(s - 0.5));
    let value = ((65535u - pr.depth_q) << 16u) | (pr.value << 8u) | (pr.lidar + 1u);
    for (var dy = -r; dy <= r; dy++) {
        for (var dx = -r; dx <= r; dx++) {
            let q = center + vec2<i32>(dx, dy);
            let d = vec2<f32>(q) + vec2<f32>(0.5) - pr.target_px;
            if (dot(d, d) <= s * s && q.x >= 0 && q.y >= 0 && q.x < w && q.y < h) {
                atomicMax(&splats[q.y * w + q.x], value);
            }
        }
    }
}
