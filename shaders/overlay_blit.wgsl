// Resolves the overlay's splat buffer (written by `lidar_overlay.wgsl`, one u32 per pixel of the
// callback's viewport) into colours inside egui's render pass: one triangle covering the
// viewport; empty pixels are transparent, others take the colour map (or the LiDAR palette) at
// the point's 8-bit value, premultiplied by the opacity.

struct Resolve {
    viewport_size_px: vec2<f32>,
    // 0 range, 1 intensity, 2 height, 3 LiDAR.
    color_mode: u32,
    opacity: f32,
};

@group(0) @binding(0) var<uniform> r: Resolve;
@group(0) @binding(1) var<storage, read> splats: array<u32>;

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) uv: vec2<f32>,
};

@vertex
fn vs_main(@builtin(vertex_index) vi: u32) -> VertexOut {
    // (-1,-1), (3,-1), (-1,3): one triangle covers the viewport.
    let x = f32((vi << 1u) & 2u) * 2.0 - 1.0;
    let y = f32(vi & 2u) * 2.0 - 1.0;
    var out: VertexOut;
    out.clip = vec4<f32>(x, y, 0.0, 1.0);
    out.uv = vec2<f32>(0.5 * (x + 1.0), 0.5 * (1.0 - y));
    return out;
}

// Turbo-like colour map, t in [0, 1].
fn colormap(t_in: f32) -> vec3<f32> {
    let t = clamp(t_in, 0.0, 1.0);
    let r = 0.13572138 + t * (4.6153926 + t * (-42.66032258 + t * (132.13108234 + t * (-152.94239396 + t * 59.28637943))));
    let g = 0.09140261 + t * (2.19418839 + t * (4.84296658 + t * (-14.18503333 + t * (4.27729857 + t * 2.82956604))));
    let b = 0.1066733 + t * (12.64194608 + t * (-60.58204836 + t * (110.36276771 + t * (-89.90310912 + t * 27.34824973))));
    return clamp(vec3<f32>(r, g, b), vec3<f32>(0.0), vec3<f32>(1.0));
}

// One colour per LiDAR (the same as the CPU path's).
const PALETTE = array<vec3<f32>, 8>(
    vec3<f32>(1.0, 0.35, 0.2), vec3<f32>(0.2, 0.8, 1.0), vec3<f32>(0.45, 1.0, 0.3),
    vec3<f32>(1.0, 0.85, 0.15), vec3<f32>(0.85, 0.4, 1.0), vec3<f32>(1.0, 1.0, 1.0),
    vec3<f32>(1.0, 0.5, 0.7), vec3<f32>(0.5, 0.6, 1.0),
);

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    let size = vec2<i32>(r.viewport_size_px);
    let q = clamp(vec2<i32>(floor(in.uv * r.viewport_size_px)), vec2<i32>(0), size - vec2<i32>(1));
    let s = splats[q.y * size.x + q.x];
    if (s == 0u) {
        discard;
    }
    var rgb: vec3<f32>;
    if (r.color_mode == 3u) {
        rgb = PALETTE[min((s & 0xFFu) - 1u, 7u)];
    } else {
        rgb = colormap(f32((s >> 8u) & 0xFFu) / 255.0);
    }
    // Premultiplied alpha, as egui's render target expects.
    return vec4<f32>(rgb * r.opacity, r.opacity);
}
