//! The camera viewport's LiDAR overlay on the GPU: a wgpu paint callback running
//! `shaders/lidar_overlay.wgsl`.
//!
//! Points stay on the GPU in their LiDAR frames with a firing-time bucket index; only the small
//! per-bucket `camera_from_lidar` table and the uniforms are uploaded when the extrinsics change,
//! so an edit re-projects every point in the next frame without CPU work. Points are ordered
//! far to near (range from their LiDAR) so nearer splats are drawn over farther ones.

use std::sync::Arc;

use eframe::egui_wgpu::{self, CallbackResources, CallbackTrait, RenderState, ScreenDescriptor};
use eframe::wgpu;
use eframe::wgpu::util::DeviceExt;

use crate::geometry::Rigid;
use crate::geometry::camera::{CameraIntrinsics, CameraModel};

const SHADER: &str = include_str!("../../shaders/lidar_overlay.wgsl");

/// One point as the vertex shader reads it.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuPoint {
    pub position_intensity: [f32; 4],
    pub bucket: u32,
}

/// Must match `Uniforms` in the shader (96 bytes).
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
    pub color_mode: u32,
    pub point_size_px: f32,
    pub opacity: f32,
    pub range_min_m: f32,
    pub range_max_m: f32,
    pub intensity_max: f32,
    pub _pad: f32,
}

impl Uniforms {
    pub fn camera(intr: &CameraIntrinsics) -> Self {
        let d = |i: usize| intr.distortion.get(i).copied().unwrap_or(0.0) as f32;
        let (model, radtan0, radtan1) = match intr.model {
            CameraModel::Equidistant => (1, [d(0), d(1), d(2), d(3)], [0.0; 4]),
            CameraModel::Pinhole => (0, [0.0; 4], [0.0; 4]),
            _ => (0, [d(0), d(1), d(2), d(3)], [d(4), d(5), d(6), d(7)]),
        };
        Self {
            focal: [intr.fx as f32, intr.fy as f32],
            principal: [intr.cx as f32, intr.cy as f32],
            image_size: [intr.width as f32, intr.height as f32],
            radtan0,
            radtan1,
            model,
            ..Self::default()
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

struct Resources {
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    uniforms: wgpu::Buffer,
    transforms: wgpu::Buffer,
    transforms_capacity: u64,
    bind_group: wgpu::BindGroup,
    points: Option<(u64, wgpu::Buffer, u32)>,
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

/// Create the pipeline once, at app start. Returns false when there is no wgpu renderer.
pub fn install(render_state: Option<&RenderState>) -> bool {
    let Some(rs) = render_state else {
        return false;
    };
    let device = &rs.device;
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("lidar_overlay.wgsl"),
        source: wgpu::ShaderSource::Wgsl(SHADER.into()),
    });
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("rigcal overlay"),
        entries: &[
            wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            },
            wgpu::BindGroupLayoutEntry {
                binding: 1,
                visibility: wgpu::ShaderStages::VERTEX,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage { read_only: true },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            },
        ],
    });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("rigcal overlay"),
        bind_group_layouts: &[Some(&layout)],
        immediate_size: 0,
    });
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
    let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("rigcal overlay"),
        layout: Some(&pipeline_layout),
        vertex: wgpu::VertexState {
            module: &module,
            entry_point: Some("vs_main"),
            compilation_options: Default::default(),
            buffers: &[Some(wgpu::VertexBufferLayout {
                array_stride: std::mem::size_of::<GpuPoint>() as u64,
                step_mode: wgpu::VertexStepMode::Instance,
                attributes: &attributes,
            })],
        },
        primitive: wgpu::PrimitiveState::default(),
        depth_stencil: None,
        multisample: wgpu::MultisampleState::default(),
        fragment: Some(wgpu::FragmentState {
            module: &module,
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
    let uniforms = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("rigcal overlay uniforms"),
        contents: bytemuck::bytes_of(&Uniforms::default()),
        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
    });
    let transforms = transform_buffer(device, 256);
    let bind_group = bind_group(device, &layout, &uniforms, &transforms);
    rs.renderer.write().callback_resources.insert(Resources {
        pipeline,
        layout,
        uniforms,
        transforms,
        transforms_capacity: 256,
        bind_group,
        points: None,
    });
    true
}

/// One frame's draw of the overlay.
pub struct OverlayCallback {
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
        _encoder: &mut wgpu::CommandEncoder,
        resources: &mut CallbackResources,
    ) -> Vec<wgpu::CommandBuffer> {
        let Some(r) = resources.get_mut::<Resources>() else {
            return Vec::new();
        };
        if r.points.as_ref().map(|p| p.0) != Some(self.points_key) {
            r.points = (!self.points.is_empty()).then(|| {
                let buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("rigcal lidar points"),
                    contents: bytemuck::cast_slice(&self.points),
                    usage: wgpu::BufferUsages::VERTEX,
                });
                (self.points_key, buf, self.points.len() as u32)
            });
        }
        let needed = self.transforms.len() as u64;
        if needed > r.transforms_capacity {
            r.transforms_capacity = needed.next_power_of_two();
            r.transforms = transform_buffer(device, r.transforms_capacity);
            r.bind_group = bind_group(device, &r.layout, &r.uniforms, &r.transforms);
        }
        if !self.transforms.is_empty() {
            queue.write_buffer(&r.transforms, 0, bytemuck::cast_slice(&self.transforms));
        }
        queue.write_buffer(&r.uniforms, 0, bytemuck::bytes_of(&self.uniforms));
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
        let Some((_, points, count)) = &r.points else {
            return;
        };
        render_pass.set_pipeline(&r.pipeline);
        render_pass.set_bind_group(0, &r.bind_group, &[]);
        render_pass.set_vertex_buffer(0, points.slice(..));
        render_pass.draw(0..6, 0..*count);
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
        // WGSL: Uniforms is 96 bytes (checked against naga in tests/shaders.rs); a point is a
        // vec4<f32> and a u32.
        assert_eq!(std::mem::size_of::<Uniforms>(), 96);
        assert_eq!(std::mem::size_of::<GpuPoint>(), 20);
    }
}
