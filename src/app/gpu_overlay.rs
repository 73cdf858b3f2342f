//! The camera viewport's LiDAR overlay on the GPU: a wgpu paint callback running
//! `shaders/lidar_overlay.wgsl`, then `shaders/overlay_blit.wgsl`.
//!
//! Points stay on the GPU in their LiDAR frames with a firing-time bucket index; only the small
//! per-bucket `camera_from_lidar` table and the uniforms are uploaded when the extrinsics change,
//! so an edit re-projects every point in the next frame without CPU work. Occlusion: in
//! `prepare` each viewport (a *slot*: one per camera tile) renders into its own offscreen
//! colour and depth target, first a depth-only pass of large splats, then the coloured points
//! with a depth test (see the shader), so points behind nearer surfaces are not drawn; `paint`
//! then blends that target into egui's pass. Point buffers are shared between slots by key.

use std::collections::HashMap;
use std::sync::Arc;

use eframe::egui_wgpu::{self, CallbackResources, CallbackTrait, RenderState, ScreenDescriptor};
use eframe::wgpu;
use eframe::wgpu::util::DeviceExt;

use crate::geometry::Rigid;
use crate::geometry::camera::{CameraIntrinsics, CameraModel};

const SHADER: &str = include_str!("../../shaders/lidar_overlay.wgsl");
const BLIT_SHADER: &str = include_str!("../../shaders/overlay_blit.wgsl");
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// Point buffers kept on the GPU (a grid of cameras usually shares one or two).
const POINT_BUFFERS: usize = 8;

/// One point as the vertex shader reads it.
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

/// Must match `Uniforms` in the shader (256 bytes).
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
    /// Radius of the depth-only occlusion splats (physical px); 0 disables occlusion.
    pub occlusion_px: f32,
    /// Image pixels shown: `view_min .. view_min + view_size` (zoom and pan).
    pub view_min: [f32; 2],
    pub view_size: [f32; 2],
    pub height_min_m: f32,
    pub height_max_m: f32,
    /// A point is hidden when something is nearer by more than this fraction of its range.
    pub depth_tolerance: f32,
    pub _pad: f32,
    /// Per LiDAR: the z row of `vehicle_from_lidar`.
    pub height_rows: [[f32; 4]; 8],
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

/// An offscreen colour + depth target the size of one viewport.
struct Target {
    size: [u32; 2],
    color: wgpu::TextureView,
    depth: wgpu::TextureView,
    blit: wgpu::BindGroup,
}

/// Per viewport (camera tile): its uniforms, transforms and target.
struct Slot {
    uniforms: wgpu::Buffer,
    transforms: wgpu::Buffer,
    transforms_capacity: u64,
    bind_group: wgpu::BindGroup,
    target: Option<Target>,
}

struct Resources {
    depth_pipeline: wgpu::RenderPipeline,
    color_pipeline: wgpu::RenderPipeline,
    blit_pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    blit_layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
    target_format: wgpu::TextureFormat,
    /// Point buffers by key, most recently used last.
    points: Vec<(u64, wgpu::Buffer, u32)>,
    slots: HashMap<u64, Slot>,
}

fn bind_group(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    uniforms: &wgpu::Buffer,
    transforms: &wgpu::Buffer,
) -> wgpu::BindGroup {
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("rigcal overlay"),
        layout,
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: uniforms.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: transforms.as_entire_binding(),
            },
        ],
    })
}

fn transform_buffer(device: &wgpu::Device, count: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("rigcal camera_from_lidar"),
        size: count.max(1) * 64,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

fn layout_entry(binding: u32, ty: wgpu::BindingType) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
        ty,
        count: None,
    }
}

fn point_pipeline(
    device: &wgpu::Device,
    layout: &wgpu::PipelineLayout,
    module: &wgpu::ShaderModule,
    target_format: wgpu::TextureFormat,
    color: Option<wgpu::TextureFormat>,
) -> wgpu::RenderPipeline {
    let attributes = [
        wgpu::VertexAttribute {
            format: wgpu::VertexFormat::Float32x4,
            offset: 0,
            shader_location: 0,
        },
        wgpu::VertexAttribute {
            format: wgpu::VertexFormat::Uint32,
            offset: 16,
            shader_location: 1,
        },
    ];
    // Both passes share one render pass with a colour attachment; the depth pass writes none.
    let targets = [Some(wgpu::ColorTargetState {
        format: color.unwrap_or(target_format),
        blend: color.map(|_| wgpu::BlendState::PREMULTIPLIED_ALPHA_BLENDING),
        write_mask: if color.is_some() {
            wgpu::ColorWrites::ALL
        } else {
            wgpu::ColorWrites::empty()
        },
    })];
    let (vs, fs, label) = if color.is_some() {
        ("vs_color", "fs_color", "rigcal overlay colour")
    } else {
        ("vs_depth", "fs_depth", "rigcal overlay depth")
    };
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(label),
        layout: Some(layout),
        vertex: wgpu::VertexState {
            module,
            entry_point: Some(vs),
            compilation_options: Default::default(),
            buffers: &[Some(wgpu::VertexBufferLayout {
                array_stride: std::mem::size_of::<GpuPoint>() as u64,
                step_mode: wgpu::VertexStepMode::Instance,
                attributes: &attributes,
            })],
        },
        primitive: wgpu::PrimitiveState::default(),
        depth_stencil: Some(wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(color.is_none()),
            depth_compare: Some(if color.is_none() {
                wgpu::CompareFunction::Less
            } else {
                wgpu::CompareFunction::LessEqual
            }),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: wgpu::MultisampleState::default(),
        fragment: Some(wgpu::FragmentState {
            module,
            entry_point: Some(fs),
            compilation_options: Default::default(),
            targets: &targets,
        }),
        multiview_mask: None,
        cache: None,
    })
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
    let buffer = |ty| wgpu::BindingType::Buffer {
        ty,
        has_dynamic_offset: false,
        min_binding_size: None,
    };
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("rigcal overlay"),
        entries: &[
            layout_entry(0, buffer(wgpu::BufferBindingType::Uniform)),
            layout_entry(
                1,
                buffer(wgpu::BufferBindingType::Storage { read_only: true }),
            ),
        ],
    });
    let blit_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("rigcal overlay blit"),
        entries: &[
            layout_entry(
                0,
                wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Float { filterable: true },
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: false,
                },
            ),
            layout_entry(
                1,
                wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
            ),
        ],
    });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("rigcal overlay"),
        bind_group_layouts: &[Some(&layout)],
        immediate_size: 0,
    });
    let blit_pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("rigcal overlay blit"),
        bind_group_layouts: &[Some(&blit_layout)],
        immediate_size: 0,
    });
    let format = rs.target_format;
    let depth_pipeline = point_pipeline(device, &pipeline_layout, &module, format, None);
    let color_pipeline = point_pipeline(device, &pipeline_layout, &module, format, Some(format));
    let blit_pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("rigcal overlay blit"),
        layout: Some(&blit_pipeline_layout),
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
    let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
        label: Some("rigcal overlay blit"),
        ..Default::default()
    });
    rs.renderer.write().callback_resources.insert(Resources {
        depth_pipeline,
        color_pipeline,
        blit_pipeline,
        layout,
        blit_layout,
        sampler,
        target_format: rs.target_format,
        points: Vec::new(),
        slots: HashMap::new(),
    });
    true
}

impl Resources {
    fn new_slot(&self, device: &wgpu::Device) -> Slot {
        let uniforms = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("rigcal overlay uniforms"),
            contents: bytemuck::bytes_of(&Uniforms::default()),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        });
        let transforms = transform_buffer(device, 256);
        let bind_group = bind_group(device, &self.layout, &uniforms, &transforms);
        Slot {
            uniforms,
            transforms,
            transforms_capacity: 256,
            bind_group,
            target: None,
        }
    }

    fn new_target(&self, device: &wgpu::Device, size: [u32; 2]) -> Target {
        let texture = |label, format, usage| {
            device
                .create_texture(&wgpu::TextureDescriptor {
                    label: Some(label),
                    size: wgpu::Extent3d {
                        width: size[0],
                        height: size[1],
                        depth_or_array_layers: 1,
                    },
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format,
                    usage,
                    view_formats: &[],
                })
                .create_view(&Default::default())
        };
        let color = texture(
            "rigcal overlay colour",
            self.target_format,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
        );
        let depth = texture(
            "rigcal overlay depth",
            DEPTH_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
        );
        let blit = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("rigcal overlay blit"),
            layout: &self.blit_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::TextureView(&color),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::Sampler(&self.sampler),
                },
            ],
        });
        Target {
            size,
            color,
            depth,
            blit,
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
            let buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("rigcal lidar points"),
                contents: bytemuck::cast_slice(points),
                usage: wgpu::BufferUsages::VERTEX,
            });
            self.points.push((key, buf, points.len() as u32));
            if self.points.len() > POINT_BUFFERS {
                self.points.remove(0);
            }
        }
        Some(self.points.len() - 1)
    }
}

/// One frame's draw of the overlay in one viewport.
pub struct OverlayCallback {
    /// The viewport (camera tile) this draw belongs to; each has its own offscreen target.
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
        let target = needs_target.then(|| r.new_target(device, size));
        let Some(slot) = r.slots.get_mut(&self.slot) else {
            return Vec::new();
        };
        if let Some(t) = target {
            slot.target = Some(t);
        }
        let needed = self.transforms.len() as u64;
        if needed > slot.transforms_capacity {
            slot.transforms_capacity = needed.next_power_of_two();
            slot.transforms = transform_buffer(device, slot.transforms_capacity);
            slot.bind_group = bind_group(device, &r.layout, &slot.uniforms, &slot.transforms);
        }
        if !self.transforms.is_empty() {
            queue.write_buffer(&slot.transforms, 0, bytemuck::cast_slice(&self.transforms));
        }
        queue.write_buffer(&slot.uniforms, 0, bytemuck::bytes_of(&self.uniforms));
        let Some(target) = &slot.target else {
            return Vec::new();
        };
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("rigcal overlay"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &target.color,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &target.depth,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Discard,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        if let Some(i) = points {
            let (_, buffer, count) = &r.points[i];
            pass.set_bind_group(0, &slot.bind_group, &[]);
            pass.set_vertex_buffer(0, buffer.slice(..));
            if self.uniforms.occlusion_px > 0.0 {
                pass.set_pipeline(&r.depth_pipeline);
                pass.draw(0..6, 0..*count);
            }
            pass.set_pipeline(&r.color_pipeline);
            pass.draw(0..6, 0..*count);
        }
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
        render_pass.set_pipeline(&r.blit_pipeline);
        render_pass.set_bind_group(0, &target.blit, &[]);
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
        // WGSL: Uniforms is 256 bytes (checked against naga in tests/shaders.rs); a point is a
        // vec4<f32> and a u32.
        assert_eq!(std::mem::size_of::<Uniforms>(), 256);
        assert_eq!(std::mem::size_of::<GpuPoint>(), 20);
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
