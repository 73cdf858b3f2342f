//! The camera viewport's LiDAR overlay on the GPU: compute shaders in
//! `shaders/lidar_overlay.wgsl` splat the points, `shaders/overlay_blit.wgsl` resolves them into
//! egui's render pass (a wgpu paint callback).
//!
//! Points stay on the GPU in their LiDAR frames with a firing-time bucket index; only the small
//! per-bucket `camera_from_lidar` table and the uniforms are uploaded when the extrinsics change,
//! so an edit re-projects every point in the next frame without CPU work. Each viewport (a
//! *slot*: one per camera tile) has its own splat buffers. In `prepare`, one compute pass splats
//! depth for occlusion and then the visible points (see the shader); `paint` draws one triangle
//! that turns the splat buffer into colours. Point buffers are shared between slots by key.

use std::collections::HashMap;
use std::sync::Arc;

use eframe::egui_wgpu::{self, CallbackResources, CallbackTrait, RenderState, ScreenDescriptor};
use eframe::wgpu;
use eframe::wgpu::util::DeviceExt;

use crate::geometry::Rigid;
use crate::geometry::camera::{CameraIntrinsics, CameraModel};

const SHADER: &str = include_str!("../../shaders/lidar_overlay.wgsl");
const BLIT_SHADER: &str = include_str!("../../shaders/overlay_blit.wgsl");
/// Point buffers kept on the GPU (a grid of cameras usually shares one or two).
const POINT_BUFFERS: usize = 8;
/// Must match `GROUP`, `ROW` and `OCCLUSION_CELL` in the shader.
const GROUP: u32 = 64;
const MAX_GROUPS_X: u32 = 65535;
const OCCLUSION_CELL: u32 = 4;

/// One point as the shader reads it (five 32-bit words).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuPoint {
    pub position_intensity: [f32; 4],
    /// Bits 0..24: firing-time bucket; bits 24..32: LiDAR index (colour by LiDAR, height row).
    pub packed: u32,
}

/// Pack a bucket index (< 2^24) and a LiDAR index (< 8 are distinguished) into one u32.
pub fn pack_bucket(bucket: u32, lidar: u32) -> u32 {
    (bucket & 0x00FF_FFFF) | (lidar.min(255) << 24)
}

/// Must match `Uniforms` in the shader (272 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Uniforms {
    pub focal: [f32; 2],
    pub principal: [f32; 2],
    pub image_size: [f32; 2],
    pub viewport_size_px: [f32; 2],
    pub radtan0: [f32; 4],
    pub radtan1: [f32; 4],
    pub model: u32,
    /// 0 range, 1 intensity, 2 height (vehicle frame), 3 LiDAR.
    pub color_mode: u32,
    pub point_size_px: f32,
    pub opacity: f32,
    pub range_min_m: f32,
    pub range_max_m: f32,
    pub intensity_max: f32,
    /// Radius of the occlusion splats (physical px); 0 disables occlusion.
    pub occlusion_px: f32,
    /// Image pixels shown: `view_min .. view_min + view_size` (zoom and pan).
    pub view_min: [f32; 2],
    pub view_size: [f32; 2],
    pub height_min_m: f32,
    pub height_max_m: f32,
    /// A point is hidden when something is nearer by more than this fraction of its range.
    pub depth_tolerance: f32,
    /// Number of points (set when drawing).
    pub count: u32,
    /// Per LiDAR: the z row of `vehicle_from_lidar`.
    pub height_rows: [[f32; 4]; 8],
    /// Camera poses per firing-time bucket in the transform table: 1, or a rolling shutter's
    /// rows (odd, at most [`crate::geometry::SAMPLED_ROWS`]; 0 counts as 1).
    pub rows: u32,
    pub _pad: [u32; 3],
}

/// Must match `Resolve` in `overlay_blit.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct ResolveUniforms {
    viewport_size_px: [f32; 2],
    color_mode: u32,
    opacity: f32,
}

impl Uniforms {
    pub fn camera(intr: &CameraIntrinsics) -> Self {
        let d = |i: usize| intr.distortion.get(i).copied().unwrap_or(0.0) as f32;
        let (model, radtan0, radtan1) = match intr.model {
            CameraModel::Equidistant => (1, [d(0), d(1), d(2), d(3)], [0.0; 4]),
            CameraModel::Pinhole => (0, [0.0; 4], [0.0; 4]),
            _ => (0, [d(0), d(1), d(2), d(3)], [d(4), d(5), d(6), d(7)]),
        };
        let image_size = [intr.width as f32, intr.height as f32];
        Self {
            focal: [intr.fx as f32, intr.fy as f32],
            principal: [intr.cx as f32, intr.cy as f32],
            image_size,
            view_size: image_size,
            radtan0,
            radtan1,
            model,
            opacity: 1.0,
            range_max_m: 80.0,
            height_min_m: -2.0,
            height_max_m: 4.0,
            depth_tolerance: 0.05,
            ..Self::default()
        }
    }

    /// Set the z row of `vehicle_from_lidar` for LiDAR `index` (colour by height).
    pub fn set_height_row(&mut self, index: usize, vehicle_from_lidar: Rigid) {
        if let Some(row) = self.height_rows.get_mut(index) {
            let m = vehicle_from_lidar.to_mat4();
            *row = [m.x_axis.z, m.y_axis.z, m.z_axis.z, m.w_axis.z].map(|v| v as f32);
        }
    }
}

/// Column-major f32 matrices for the shader's `camera_from_lidar` table.
pub fn transforms_f32(transforms: &[Rigid]) -> Vec<[[f32; 4]; 4]> {
    transforms
        .iter()
        .map(|t| t.to_mat4().as_mat4().to_cols_array_2d())
        .collect()
}

/// The splat buffers of one viewport size.
struct Target {
    size: [u32; 2],
    occlusion: wgpu::Buffer,
    splats: wgpu::Buffer,
    resolve_group: wgpu::BindGroup,
}

/// Per viewport (camera tile): uniforms, transforms, splat buffers and the compute bind group
/// (remade when the point buffer, the transforms buffer or the target changes).
struct Slot {
    uniforms: wgpu::Buffer,
    resolve_uniforms: wgpu::Buffer,
    transforms: wgpu::Buffer,
    transforms_capacity: u64,
    target: Option<Target>,
    group: Option<((u64, u64, [u32; 2]), wgpu::BindGroup)>,
}

struct Resources {
    occlusion_pipeline: wgpu::ComputePipeline,
    splat_pipeline: wgpu::ComputePipeline,
    resolve_pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    resolve_layout: wgpu::BindGroupLayout,
    /// Point buffers by key, most recently used last.
    points: Vec<(u64, wgpu::Buffer, u32)>,
    slots: HashMap<u64, Slot>,
}

fn transform_buffer(device: &wgpu::Device, count: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("rigcal camera_from_lidar"),
        size: count.max(1) * 64,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

fn entry(
    binding: u32,
    visibility: wgpu::ShaderStages,
    ty: wgpu::BufferBindingType,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer {
            ty,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

fn buffer_entry(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry {
        binding,
        resource: buffer.as_entire_binding(),
    }
}

/// Create the pipelines once, at app start. Returns false when there is no wgpu renderer.
pub fn install(render_state: Option<&RenderState>) -> bool {
    let Some(rs) = render_state else {
        return false;
    };
    let device = &rs.device;
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("lidar_overlay.wgsl"),
        source: wgpu::ShaderSource::Wgsl(SHADER.into()),
    });
    let blit_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("overlay_blit.wgsl"),
        source: wgpu::ShaderSource::Wgsl(BLIT_SHADER.into()),
    });
    use wgpu::BufferBindingType as B;
    let cs = wgpu::ShaderStages::COMPUTE;
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("rigcal overlay"),
        entries: &[
            entry(0, cs, B::Uniform),
            entry(1, cs, B::Storage { read_only: true }),
            entry(2, cs, B::Storage { read_only: true }),
            entry(3, cs, B::Storage { read_only: false }),
            entry(4, cs, B::Storage { read_only: false }),
        ],
    });
    let fs = wgpu::ShaderStages::FRAGMENT;
    let resolve_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("rigcal overlay resolve"),
        entries: &[
            entry(0, fs, B::Uniform),
            entry(1, fs, B::Storage { read_only: true }),
        ],
    });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("rigcal overlay"),
        bind_group_layouts: &[Some(&layout)],
        immediate_size: 0,
    });
    let resolve_pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("rigcal overlay resolve"),
        bind_group_layouts: &[Some(&resolve_layout)],
        immediate_size: 0,
    });
    let compute = |entry_point: &str| {
        device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(entry_point),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some(entry_point),
            compilation_options: Default::default(),
            cache: None,
        })
    };
    let occlusion_pipeline = compute("cs_occlusion");
    let splat_pipeline = compute("cs_splat");
    let resolve_pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("rigcal overlay resolve"),
        layout: Some(&resolve_pipeline_layout),
        vertex: wgpu::VertexState {
            module: &blit_module,
            entry_point: Some("vs_main"),
            compilation_options: Default::default(),
            buffers: &[],
        },
        primitive: wgpu::PrimitiveState::default(),
        depth_stencil: None,
        multisample: wgpu::MultisampleState::default(),
        fragment: Some(wgpu::FragmentState {
            module: &blit_module,
            entry_point: Some("fs_main"),
            compilation_options: Default::default(),
            targets: &[Some(wgpu::ColorTargetState {
                format: rs.target_format,
                blend: Some(wgpu::BlendState::PREMULTIPLIED_ALPHA_BLENDING),
                write_mask: wgpu::ColorWrites::ALL,
            })],
        }),
        multiview_mask: None,
        cache: None,
    });
    rs.renderer.write().callback_resources.insert(Resources {
        occlusion_pipeline,
        splat_pipeline,
        resolve_pipeline,
        layout,
        resolve_layout,
        points: Vec::new(),
        slots: HashMap::new(),
    });
    true
}

impl Resources {
    fn new_slot(&self, device: &wgpu::Device) -> Slot {
        let uniform = |label, size| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        Slot {
            uniforms: uniform(
                "rigcal overlay uniforms",
                std::mem::size_of::<Uniforms>() as u64,
            ),
            resolve_uniforms: uniform(
                "rigcal overlay resolve uniforms",
                std::mem::size_of::<ResolveUniforms>() as u64,
            ),
            transforms: transform_buffer(device, 256),
            transforms_capacity: 256,
            target: None,
            group: None,
        }
    }

    fn new_target(&self, device: &wgpu::Device, slot: &Slot, size: [u32; 2]) -> Target {
        let storage = |label, words: u64| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: words.max(1) * 4,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        let cells = |n: u32| n.div_ceil(OCCLUSION_CELL) as u64;
        let occlusion = storage("rigcal overlay occlusion", cells(size[0]) * cells(size[1]));
        let splats = storage("rigcal overlay splats", size[0] as u64 * size[1] as u64);
        let resolve_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("rigcal overlay resolve"),
            layout: &self.resolve_layout,
            entries: &[
                buffer_entry(0, &slot.resolve_uniforms),
                buffer_entry(1, &splats),
            ],
        });
        Target {
            size,
            occlusion,
            splats,
            resolve_group,
        }
    }

    /// The point buffer for `key`, uploading `points` if it is not on the GPU yet.
    fn points(&mut self, device: &wgpu::Device, key: u64, points: &[GpuPoint]) -> Option<usize> {
        if points.is_empty() {
            return None;
        }
        if let Some(i) = self.points.iter().position(|p| p.0 == key) {
            let entry = self.points.remove(i);
            self.points.push(entry);
        } else {
            // More points than one storage binding holds (dense LiDARs, many sweeps accumulated)
            // would be a validation error: keep the nearest, which come last.
            let points = &points[points.len() - points.len().min(max_points(&device.limits()))..];
            let buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("rigcal lidar points"),
                contents: bytemuck::cast_slice(points),
                usage: wgpu::BufferUsages::STORAGE,
            });
            self.points.push((key, buf, points.len() as u32));
            if self.points.len() > POINT_BUFFERS {
                self.points.remove(0);
            }
        }
        Some(self.points.len() - 1)
    }
}

/// How many points one storage buffer binding of a device with `limits` holds.
pub fn max_points(limits: &wgpu::Limits) -> usize {
    let bytes = limits
        .max_storage_buffer_binding_size
        .min(limits.max_buffer_size);
    usize::try_from(bytes / std::mem::size_of::<GpuPoint>() as u64).unwrap_or(usize::MAX)
}

/// One frame's draw of the overlay in one viewport.
pub struct OverlayCallback {
    /// The viewport (camera tile) this draw belongs to; each has its own splat buffers.
    pub slot: u64,
    /// Identifies `points`; they are uploaded only when it changes.
    pub points_key: u64,
    pub points: Arc<Vec<GpuPoint>>,
    pub transforms: Vec<[[f32; 4]; 4]>,
    pub uniforms: Uniforms,
}

impl CallbackTrait for OverlayCallback {
    fn prepare(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        _screen: &ScreenDescriptor,
        encoder: &mut wgpu::CommandEncoder,
        resources: &mut CallbackResources,
    ) -> Vec<wgpu::CommandBuffer> {
        let Some(r) = resources.get_mut::<Resources>() else {
            return Vec::new();
        };
        let points = r.points(device, self.points_key, &self.points);
        if !r.slots.contains_key(&self.slot) {
            let slot = r.new_slot(device);
            r.slots.insert(self.slot, slot);
        }
        let size = self
            .uniforms
            .viewport_size_px
            .map(|v| (v.round() as u32).clamp(1, 8192));
        let needs_target = r
            .slots
            .get(&self.slot)
            .is_none_or(|s| s.target.as_ref().is_none_or(|t| t.size != size));
        if needs_target {
            let target = r
                .slots
                .get(&self.slot)
                .map(|slot| r.new_target(device, slot, size));
            if let Some(slot) = r.slots.get_mut(&self.slot) {
                slot.target = target;
            }
        }
        let Some(slot) = r.slots.get_mut(&self.slot) else {
            return Vec::new();
        };
        let needed = self.transforms.len() as u64;
        if needed > slot.transforms_capacity {
            slot.transforms_capacity = needed.next_power_of_two();
            slot.transforms = transform_buffer(device, slot.transforms_capacity);
            slot.group = None;
        }
        if !self.transforms.is_empty() {
            queue.write_buffer(&slot.transforms, 0, bytemuck::cast_slice(&self.transforms));
        }
        let count = points.map_or(0, |i| r.points[i].2);
        let mut uniforms = self.uniforms;
        uniforms.viewport_size_px = [size[0] as f32, size[1] as f32];
        uniforms.count = count;
        queue.write_buffer(&slot.uniforms, 0, bytemuck::bytes_of(&uniforms));
        let resolve = ResolveUniforms {
            viewport_size_px: uniforms.viewport_size_px,
            color_mode: uniforms.color_mode,
            opacity: uniforms.opacity,
        };
        queue.write_buffer(&slot.resolve_uniforms, 0, bytemuck::bytes_of(&resolve));
        let Some(target) = &slot.target else {
            return Vec::new();
        };
        encoder.clear_buffer(&target.splats, 0, None);
        let Some(i) = points else {
            return Vec::new();
        };
        let group_key = (self.points_key, slot.transforms_capacity, size);
        if slot.group.as_ref().map(|g| g.0) != Some(group_key) {
            let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("rigcal overlay"),
                layout: &r.layout,
                entries: &[
                    buffer_entry(0, &slot.uniforms),
                    buffer_entry(1, &slot.transforms),
                    buffer_entry(2, &r.points[i].1),
                    buffer_entry(3, &target.occlusion),
                    buffer_entry(4, &target.splats),
                ],
            });
            slot.group = Some((group_key, group));
        }
        let Some((_, group)) = &slot.group else {
            return Vec::new();
        };
        let groups = count.div_ceil(GROUP);
        let (gx, gy) = (groups.min(MAX_GROUPS_X), groups.div_ceil(MAX_GROUPS_X));
        let occlusion = uniforms.occlusion_px > 0.0;
        if occlusion {
            encoder.clear_buffer(&target.occlusion, 0, None);
        }
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("rigcal overlay splat"),
            timestamp_writes: None,
        });
        pass.set_bind_group(0, group, &[]);
        if occlusion {
            pass.set_pipeline(&r.occlusion_pipeline);
            pass.dispatch_workgroups(gx, gy, 1);
        }
        pass.set_pipeline(&r.splat_pipeline);
        pass.dispatch_workgroups(gx, gy, 1);
        Vec::new()
    }

    fn paint(
        &self,
        _info: egui::PaintCallbackInfo,
        render_pass: &mut wgpu::RenderPass<'static>,
        resources: &CallbackResources,
    ) {
        let Some(r) = resources.get::<Resources>() else {
            return;
        };
        let Some(target) = r.slots.get(&self.slot).and_then(|s| s.target.as_ref()) else {
            return;
        };
        render_pass.set_pipeline(&r.resolve_pipeline);
        render_pass.set_bind_group(0, &target.resolve_group, &[]);
        render_pass.draw(0..3, 0..1);
    }
}

/// The paint callback for `rect` (the image's rectangle on screen).
pub fn paint_callback(rect: egui::Rect, callback: OverlayCallback) -> egui::PaintCallback {
    egui_wgpu::Callback::new_paint_callback(rect, callback)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rust_layouts_match_the_shader() {
        // WGSL: Uniforms is 272 bytes (checked against naga in tests/shaders.rs); a point is a
        // vec4<f32> and a u32.
        assert_eq!(std::mem::size_of::<Uniforms>(), 272);
        assert_eq!(std::mem::size_of::<GpuPoint>(), 20);
    }

    #[test]
    fn one_binding_holds_the_points_its_size_allows() {
        // wgpu's defaults: 128 MiB per storage binding, 256 MiB per buffer.
        let limits = wgpu::Limits::default();
        assert_eq!(max_points(&limits), (128 << 20) / 20);
        let small = wgpu::Limits {
            max_buffer_size: 100,
            ..limits
        };
        assert_eq!(max_points(&small), 5);
    }
}

#[cfg(test)]
mod pack_tests {
    use super::*;

    #[test]
    fn bucket_and_lidar_pack_into_one_word() {
        let p = pack_bucket(123_456, 3);
        assert_eq!(p & 0x00FF_FFFF, 123_456);
        assert_eq!(p >> 24, 3);
    }

    #[test]
    fn height_row_is_the_vehicle_z_of_a_lidar_point() {
        let t = Rigid::new(
            glam::DQuat::from_rotation_y(0.3),
            glam::DVec3::new(1.0, 2.0, 1.5),
        );
        let mut u = Uniforms::default();
        u.set_height_row(1, t);
        let p = glam::DVec3::new(4.0, -1.0, 0.5);
        let row = u.height_rows[1];
        let z = row[0] as f64 * p.x + row[1] as f64 * p.y + row[2] as f64 * p.z + row[3] as f64;
        assert!((z - t.transform_point(p).z).abs() < 1e-5);
    }
}
