//! wgpu plumbing: device, pipelines, targets and the readback buffer. Everything is created
//! once; a frame only writes two small uniform blocks and the vertex buffer, records two
//! (or four) render passes and one copy, and maps one buffer.

use std::num::NonZeroU64;
use std::sync::mpsc;

use super::error::RenderError;

/// Byte layout of one vertex (robot-frame position, normal, albedo, face id).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub struct GpuVertex {
    pub position: [f32; 3],
    pub normal: [f32; 3],
    pub shade: f32,
    pub id: u32,
}

pub const VERTEX_BYTES: u64 = std::mem::size_of::<GpuVertex>() as u64;

/// Per-view scene uniform (matches `View` in shaders/scene.wgsl).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub struct ViewUniform {
    pub clip_from_robot: [f32; 16],
    pub light: [f32; 4],
    pub params: [f32; 4],
}

/// Per-view blur uniform (matches `Post` in shaders/post.wgsl).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub struct PostUniform {
    pub params: [f32; 4],
    pub layer: [u32; 4],
}

/// Reinterprets plain `#[repr(C)]` data of `f32`/`u32` fields as bytes.
fn bytes_of<T: Copy>(items: &[T]) -> &[u8] {
    // SAFETY: only used with the `#[repr(C)]` types above, made of 4-byte scalars with no
    // padding; every byte of them is initialised.
    unsafe { std::slice::from_raw_parts(items.as_ptr().cast::<u8>(), std::mem::size_of_val(items)) }
}

const SCENE_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R8Unorm;
const ID_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Uint;
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// Samples per pixel of the grey pass with anti-aliasing on (multisample, resolved into the
/// scene texture). A camera integrates light over each pixel, so an edge that crosses a pixel
/// gives it a mixed grey: that is what lets a tracker place edges to a fraction of a pixel.
/// Without it every edge snaps to a pixel boundary, and a near-vertical facet side is off by
/// up to half a pixel all along its length. The face-id pass stays single-sampled (ids do
/// not mix). On lavapipe it costs ~12 ms per stereo frame.
pub const ANTIALIAS_SAMPLES: u32 = 4;
pub const VIEWS: u32 = 2;

/// The GPU side of the renderer.
pub struct Gpu {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub adapter: wgpu::AdapterInfo,
    width: u32,
    height: u32,
    /// Uniform offsets must be multiples of this.
    align: u64,
    scene_pipeline: wgpu::RenderPipeline,
    /// The grey pass single-sampled (when `samples` is 1 it is the same as `scene_pipeline`).
    scene_pipeline_single: wgpu::RenderPipeline,
    samples: u32,
    scene_layers: [wgpu::TextureView; 2],
    id_pipeline: wgpu::RenderPipeline,
    post_pipeline: wgpu::RenderPipeline,
    view_uniforms: wgpu::Buffer,
    view_bind: wgpu::BindGroup,
    post_uniforms: wgpu::Buffer,
    post_bind: wgpu::BindGroup,
    vertices: wgpu::Buffer,
    vertex_capacity: u64,
    scene_texture: wgpu::Texture,
    output_layers: [wgpu::TextureView; 2],
    output_texture: wgpu::Texture,
    depth_layers: [wgpu::TextureView; 2],
    msaa_color: [wgpu::TextureView; 2],
    msaa_depth: [wgpu::TextureView; 2],
    resolved: [wgpu::Texture; 2],
    resolved_views: [wgpu::TextureView; 2],
    id_layers: [wgpu::TextureView; 2],
    id_texture: wgpu::Texture,
    readback: wgpu::Buffer,
    id_readback: wgpu::Buffer,
    /// Bytes per row in the readback buffers (256-byte aligned).
    gray_row_bytes: u32,
    id_row_bytes: u32,
}

fn layer_views(texture: &wgpu::Texture) -> [wgpu::TextureView; 2] {
    let view = |layer: u32| {
        texture.create_view(&wgpu::TextureViewDescriptor {
            dimension: Some(wgpu::TextureViewDimension::D2),
            base_array_layer: layer,
            array_layer_count: Some(1),
            ..Default::default()
        })
    };
    [view(0), view(1)]
}

/// Vulkan first (lavapipe on GPU-less machines; probing GL then only prints EGL noise), then
/// whatever `WGPU_BACKEND` allows (all backends by default).
fn request_adapter() -> Result<wgpu::Adapter, RenderError> {
    let options = wgpu::RequestAdapterOptions {
        power_preference: wgpu::PowerPreference::from_env().unwrap_or(wgpu::PowerPreference::HighPerformance),
        force_fallback_adapter: false,
        compatible_surface: None,
        ..Default::default()
    };
    let from_env = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
    if std::env::var_os("WGPU_BACKEND").is_none() {
        let mut vulkan = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        vulkan.backends = wgpu::Backends::VULKAN;
        if let Ok(a) = pollster::block_on(wgpu::Instance::new(vulkan).request_adapter(&options)) {
            return Ok(a);
        }
    }
    pollster::block_on(wgpu::Instance::new(from_env).request_adapter(&options)).map_err(|e| RenderError::NoAdapter(e.to_string()))
}

fn padded_row(bytes: u32) -> u32 {
    bytes.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT
}

impl Gpu {
    /// Opens a headless device (Vulkan preferred: lavapipe on GPU-less machines; the GL
    /// backend is a fallback) and builds everything for `width` x `height` views and up to
    /// `max_vertices` vertices per frame.
    /// `samples`: 1, or [`ANTIALIAS_SAMPLES`] for an anti-aliased grey pass.
    pub fn new(width: u32, height: u32, max_vertices: usize, samples: u32) -> Result<Self, RenderError> {
        let adapter = request_adapter()?;
        let info = adapter.get_info();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("handeye-sim"),
            required_features: wgpu::Features::empty(),
            required_limits: wgpu::Limits::downlevel_defaults().using_resolution(adapter.limits()),
            ..Default::default()
        }))
        .map_err(|e| RenderError::Device(e.to_string()))?;
        let guard = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let gpu = Self::build(device, queue, info, width, height, max_vertices, samples);
        if let Some(e) = pollster::block_on(guard.pop()) {
            return Err(RenderError::Device(format!("pipeline set-up: {e}")));
        }
        Ok(gpu)
    }

    fn build(
        device: wgpu::Device,
        queue: wgpu::Queue,
        adapter: wgpu::AdapterInfo,
        width: u32,
        height: u32,
        max_vertices: usize,
        samples: u32,
    ) -> Self {
        let align = u64::from(device.limits().min_uniform_buffer_offset_alignment).max(256);
        let scene_shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("scene.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("../../../shaders/scene.wgsl").into()),
        });
        let post_shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("post.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("../../../shaders/post.wgsl").into()),
        });

        let uniform_entry = |binding: u32, visibility: wgpu::ShaderStages, size: u64| wgpu::BindGroupLayoutEntry {
            binding,
            visibility,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: true,
                min_binding_size: NonZeroU64::new(size),
            },
            count: None,
        };
        let view_size = std::mem::size_of::<ViewUniform>() as u64;
        let post_size = std::mem::size_of::<PostUniform>() as u64;
        let view_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("view"),
            entries: &[uniform_entry(0, wgpu::ShaderStages::VERTEX, view_size)],
        });
        let post_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("post"),
            entries: &[
                uniform_entry(0, wgpu::ShaderStages::FRAGMENT, post_size),
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: false },
                        view_dimension: wgpu::TextureViewDimension::D2Array,
                        multisampled: false,
                    },
                    count: None,
                },
            ],
        });

        let vertex_attrs = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32, 3 => Uint32];
        let vertex_layout =
            wgpu::VertexBufferLayout { array_stride: VERTEX_BYTES, step_mode: wgpu::VertexStepMode::Vertex, attributes: &vertex_attrs };
        let scene_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("scene"),
            bind_group_layouts: &[Some(&view_layout)],
            immediate_size: 0,
        });
        let scene_pipeline_for = |entry: &str, format: wgpu::TextureFormat, samples: u32| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(entry),
                layout: Some(&scene_layout),
                vertex: wgpu::VertexState {
                    module: &scene_shader,
                    entry_point: Some("vs_main"),
                    compilation_options: Default::default(),
                    buffers: &[Some(vertex_layout.clone())],
                },
                primitive: wgpu::PrimitiveState {
                    topology: wgpu::PrimitiveTopology::TriangleList,
                    front_face: wgpu::FrontFace::Ccw,
                    cull_mode: Some(wgpu::Face::Back),
                    ..Default::default()
                },
                depth_stencil: Some(wgpu::DepthStencilState {
                    format: DEPTH_FORMAT,
                    depth_write_enabled: Some(true),
                    depth_compare: Some(wgpu::CompareFunction::Less),
                    stencil: Default::default(),
                    bias: Default::default(),
                }),
                multisample: wgpu::MultisampleState { count: samples, ..Default::default() },
                fragment: Some(wgpu::FragmentState {
                    module: &scene_shader,
                    entry_point: Some(entry),
                    compilation_options: Default::default(),
                    targets: &[Some(wgpu::ColorTargetState { format, blend: None, write_mask: wgpu::ColorWrites::ALL })],
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        let scene_pipeline = scene_pipeline_for("fs_shade", SCENE_FORMAT, samples);
        let scene_pipeline_single = scene_pipeline_for("fs_shade", SCENE_FORMAT, 1);
        let id_pipeline = scene_pipeline_for("fs_id", ID_FORMAT, 1);

        let post_pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("post"),
            bind_group_layouts: &[Some(&post_layout)],
            immediate_size: 0,
        });
        let post_pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("post"),
            layout: Some(&post_pipeline_layout),
            vertex: wgpu::VertexState {
                module: &post_shader,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: Default::default(),
            depth_stencil: None,
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &post_shader,
                entry_point: Some("fs_main"),
                compilation_options: Default::default(),
                targets: &[Some(wgpu::ColorTargetState {
                    format: SCENE_FORMAT,
                    blend: None,
                    write_mask: wgpu::ColorWrites::ALL,
                })],
            }),
            multiview_mask: None,
            cache: None,
        });

        let size = wgpu::Extent3d { width, height, depth_or_array_layers: VIEWS };
        let texture = |label: &str, format: wgpu::TextureFormat, usage: wgpu::TextureUsages| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size,
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        use wgpu::TextureUsages as U;
        let scene_texture = texture("scene", SCENE_FORMAT, U::RENDER_ATTACHMENT | U::TEXTURE_BINDING | U::COPY_SRC | U::COPY_DST);
        let output_texture = texture("output", SCENE_FORMAT, U::RENDER_ATTACHMENT | U::COPY_SRC);
        let depth_texture = texture("depth", DEPTH_FORMAT, U::RENDER_ATTACHMENT);
        let id_texture = texture("ids", ID_FORMAT, U::RENDER_ATTACHMENT | U::COPY_SRC);
        // Multisampled targets of the grey pass: one per view (a multisampled texture has a
        // single layer), resolved into the scene texture's layers.
        let msaa = |label: &str, format: wgpu::TextureFormat| {
            let t = device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
                mip_level_count: 1,
                sample_count: samples,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage: U::RENDER_ATTACHMENT,
                view_formats: &[],
            });
            t.create_view(&wgpu::TextureViewDescriptor::default())
        };
        let msaa_color = [msaa("msaa colour left", SCENE_FORMAT), msaa("msaa colour right", SCENE_FORMAT)];
        // Resolve targets, one single-layer texture per view, copied into the scene texture's
        // layers afterwards (resolving straight into the second layer of an array texture
        // left it black on lavapipe).
        let resolve = |label: &str| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: SCENE_FORMAT,
                usage: U::RENDER_ATTACHMENT | U::COPY_SRC,
                view_formats: &[],
            })
        };
        let resolved = [resolve("resolved left"), resolve("resolved right")];
        let resolved_views = [
            resolved[0].create_view(&wgpu::TextureViewDescriptor::default()),
            resolved[1].create_view(&wgpu::TextureViewDescriptor::default()),
        ];
        let msaa_depth = [msaa("msaa depth left", DEPTH_FORMAT), msaa("msaa depth right", DEPTH_FORMAT)];
        let scene_array = scene_texture.create_view(&wgpu::TextureViewDescriptor {
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        });

        let buffer = |label: &str, size: u64, usage: wgpu::BufferUsages| {
            device.create_buffer(&wgpu::BufferDescriptor { label: Some(label), size, usage, mapped_at_creation: false })
        };
        use wgpu::BufferUsages as B;
        let view_uniforms = buffer("view uniforms", align * u64::from(VIEWS), B::UNIFORM | B::COPY_DST);
        let post_uniforms = buffer("post uniforms", align * u64::from(VIEWS), B::UNIFORM | B::COPY_DST);
        let vertex_capacity = max_vertices.max(3) as u64;
        let vertices = buffer("vertices", vertex_capacity * VERTEX_BYTES, B::VERTEX | B::COPY_DST);
        let gray_row_bytes = padded_row(width);
        let id_row_bytes = padded_row(width * 4);
        let readback = buffer("gray readback", u64::from(gray_row_bytes * height * VIEWS), B::COPY_DST | B::MAP_READ);
        let id_readback = buffer("id readback", u64::from(id_row_bytes * height * VIEWS), B::COPY_DST | B::MAP_READ);

        let view_bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("view"),
            layout: &view_layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                    buffer: &view_uniforms,
                    offset: 0,
                    size: NonZeroU64::new(view_size),
                }),
            }],
        });
        let post_bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("post"),
            layout: &post_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: &post_uniforms,
                        offset: 0,
                        size: NonZeroU64::new(post_size),
                    }),
                },
                wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(&scene_array) },
            ],
        });

        Self {
            output_layers: layer_views(&output_texture),
            depth_layers: layer_views(&depth_texture),
            msaa_color,
            msaa_depth,
            resolved,
            resolved_views,
            id_layers: layer_views(&id_texture),
            device,
            queue,
            adapter,
            width,
            height,
            align,
            scene_pipeline,
            scene_pipeline_single,
            samples,
            scene_layers: layer_views(&scene_texture),
            id_pipeline,
            post_pipeline,
            view_uniforms,
            view_bind,
            post_uniforms,
            post_bind,
            vertices,
            vertex_capacity,
            scene_texture,
            output_texture,
            id_texture,
            readback,
            id_readback,
            gray_row_bytes,
            id_row_bytes,
        }
    }

    /// Uploads this frame's vertices and per-view uniforms.
    pub fn upload(&mut self, vertices: &[GpuVertex], views: &[ViewUniform; 2], posts: &[PostUniform; 2]) -> Result<(), RenderError> {
        if vertices.len() as u64 > self.vertex_capacity {
            return Err(RenderError::TooManyVertices { have: vertices.len(), capacity: self.vertex_capacity as usize });
        }
        self.queue.write_buffer(&self.vertices, 0, bytes_of(vertices));
        for v in 0..VIEWS as usize {
            let offset = self.align * v as u64;
            self.queue.write_buffer(&self.view_uniforms, offset, bytes_of(&views[v..v + 1]));
            self.queue.write_buffer(&self.post_uniforms, offset, bytes_of(&posts[v..v + 1]));
        }
        Ok(())
    }

    /// Draws one view into `target`; `multisampled`: into the view's multisampled targets,
    /// resolved into `target`.
    #[allow(clippy::too_many_arguments)]
    fn draw_scene(
        &self,
        enc: &mut wgpu::CommandEncoder,
        view: usize,
        target: &wgpu::TextureView,
        clear: wgpu::Color,
        pipeline: &wgpu::RenderPipeline,
        vertex_count: u32,
        multisampled: bool,
    ) {
        let (colour, resolve, depth, store) = if multisampled {
            (&self.msaa_color[view], Some(target), &self.msaa_depth[view], wgpu::StoreOp::Discard)
        } else {
            (target, None, &self.depth_layers[view], wgpu::StoreOp::Store)
        };
        let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("scene"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: colour,
                depth_slice: None,
                resolve_target: resolve,
                ops: wgpu::Operations { load: wgpu::LoadOp::Clear(clear), store },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: depth,
                depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Discard }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, &self.view_bind, &[(self.align * view as u64) as u32]);
        pass.set_vertex_buffer(0, self.vertices.slice(..u64::from(vertex_count) * VERTEX_BYTES));
        pass.draw(0..vertex_count, 0..1);
    }

    /// Renders both views as GRAY8 into `out` (left rows, then right rows, `width` bytes a
    /// row). `post` runs the blur pass; without it the shaded scene is copied as is.
    pub fn render_gray(&self, vertex_count: u32, background: f64, post: bool, out: &mut [u8]) -> Result<(), RenderError> {
        let mut enc = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("frame") });
        let clear = wgpu::Color { r: background, g: 0.0, b: 0.0, a: 1.0 };
        for view in 0..VIEWS as usize {
            if self.samples == 1 {
                self.draw_scene(&mut enc, view, &self.scene_layers[view], clear, &self.scene_pipeline_single, vertex_count, false);
                continue;
            }
            self.draw_scene(&mut enc, view, &self.resolved_views[view], clear, &self.scene_pipeline, vertex_count, true);
            enc.copy_texture_to_texture(
                wgpu::TexelCopyTextureInfo { texture: &self.resolved[view], mip_level: 0, origin: wgpu::Origin3d::ZERO, aspect: wgpu::TextureAspect::All },
                wgpu::TexelCopyTextureInfo {
                    texture: &self.scene_texture,
                    mip_level: 0,
                    origin: wgpu::Origin3d { x: 0, y: 0, z: view as u32 },
                    aspect: wgpu::TextureAspect::All,
                },
                wgpu::Extent3d { width: self.width, height: self.height, depth_or_array_layers: 1 },
            );
        }
        let source = if post {
            for view in 0..VIEWS as usize {
                let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("post"),
                    color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                        view: &self.output_layers[view],
                        depth_slice: None,
                        resolve_target: None,
                        ops: wgpu::Operations { load: wgpu::LoadOp::Clear(wgpu::Color::BLACK), store: wgpu::StoreOp::Store },
                    })],
                    depth_stencil_attachment: None,
                    timestamp_writes: None,
                    occlusion_query_set: None,
                    multiview_mask: None,
                });
                pass.set_pipeline(&self.post_pipeline);
                pass.set_bind_group(0, &self.post_bind, &[(self.align * view as u64) as u32]);
                pass.draw(0..3, 0..1);
            }
            &self.output_texture
        } else {
            &self.scene_texture
        };
        self.copy_and_read(enc, source, &self.readback, self.gray_row_bytes, 1, out)
    }

    /// Renders the face-id pass of both views into `out` (u32 per pixel, same layout).
    pub fn render_ids(&self, vertex_count: u32, out: &mut [u32]) -> Result<(), RenderError> {
        let mut enc = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("ids") });
        for view in 0..VIEWS as usize {
            self.draw_scene(&mut enc, view, &self.id_layers[view], wgpu::Color::TRANSPARENT, &self.id_pipeline, vertex_count, false);
        }
        let mut bytes = vec![0u8; out.len() * 4];
        self.copy_and_read(enc, &self.id_texture, &self.id_readback, self.id_row_bytes, 4, &mut bytes)?;
        for (o, b) in out.iter_mut().zip(bytes.chunks_exact(4)) {
            *o = u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
        }
        Ok(())
    }

    /// One copy of both layers into `buffer`, one submit, one map; strips the row padding
    /// while copying into `out`.
    fn copy_and_read(
        &self,
        mut enc: wgpu::CommandEncoder,
        texture: &wgpu::Texture,
        buffer: &wgpu::Buffer,
        row_bytes: u32,
        bytes_per_pixel: u32,
        out: &mut [u8],
    ) -> Result<(), RenderError> {
        let tight = (self.width * bytes_per_pixel) as usize;
        let expected = tight * self.height as usize * VIEWS as usize;
        if out.len() != expected {
            return Err(RenderError::OutputSize { have: out.len(), want: expected });
        }
        enc.copy_texture_to_buffer(
            texture.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer,
                layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(row_bytes), rows_per_image: Some(self.height) },
            },
            wgpu::Extent3d { width: self.width, height: self.height, depth_or_array_layers: VIEWS },
        );
        let (tx, rx) = mpsc::channel();
        enc.map_buffer_on_submit(buffer, wgpu::MapMode::Read, .., move |r| {
            let _ = tx.send(r);
        });
        let index = self.queue.submit([enc.finish()]);
        self.device
            .poll(wgpu::PollType::Wait { submission_index: Some(index), timeout: None })
            .map_err(|e| RenderError::Device(format!("poll: {e}")))?;
        rx.recv()
            .map_err(|_| RenderError::Device("map callback dropped".into()))?
            .map_err(|e| RenderError::Device(format!("map: {e}")))?;
        {
            let mapped = buffer.get_mapped_range(..).map_err(|e| RenderError::Device(format!("mapped range: {e}")))?;
            for (row, dst) in out.chunks_exact_mut(tight).enumerate() {
                let start = row * row_bytes as usize;
                dst.copy_from_slice(&mapped[start..start + tight]);
            }
        }
        buffer.unmap();
        Ok(())
    }
}
