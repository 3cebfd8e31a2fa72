//! The raster passes: every draw of a frame into one colour, AOV and depth
//! target, the nearest surface winning per pixel through the fragments'
//! exact depths (section 8.5.2's refined hit, written as the fragment's
//! depth), every draw under the frame's one [`View`].

use super::pipelines::{Geometry, Kind, Renderer};
use super::targets::{Image, Targets};
use super::{Draw, PlaneScene, View};
use crate::descriptors::cleared_attachment;
use crate::{Error, GpuContext, Result};

/// The built-in scene's background (linear).
const DEFAULT_CLEAR: [f64; 3] = [0.02, 0.02, 0.03];

impl Renderer {
    /// Times `frames` renders of `scene` recorded into one submission (by
    /// GPU timestamps where the device has them), so the benchmarks
    /// (section 8.6's comparison) measure the passes and not the readback.
    pub fn time(
        &self,
        ctx: &GpuContext,
        scene: &PlaneScene,
        frames: u32,
    ) -> Result<crate::timing::Timing> {
        check_frame(&scene.view, &[(self, &scene.draw)])?;
        let groups = self.uniforms(ctx, &scene.view, &scene.draw)?;
        Targets::check(ctx, scene.view.size)?;
        let targets = ctx.checked("allocating the frame's targets", || {
            Targets::new(ctx, scene.view.size)
        })?;
        crate::timing::time_frames(ctx, frames, |encoder, query| {
            record(
                encoder,
                &targets,
                &[(self, groups.clone())],
                DEFAULT_CLEAR,
                frames.max(1),
                query,
            );
            Ok(())
        })
    }

    /// Renders `scene` offscreen and reads colour and AOV back: the
    /// one-face case of [`render_faces`], on the built-in background.
    pub fn render(&self, ctx: &GpuContext, scene: &PlaneScene) -> Result<Image> {
        render_faces(ctx, &scene.view, &[(self, &scene.draw)], DEFAULT_CLEAR)
    }
}

/// A clear colour.
fn rgba([r, g, b, a]: [f64; 4]) -> wgpu::Color {
    wgpu::Color { r, g, b, a }
}

/// One draw of a frame as recorded: its renderer and bind groups.
type Recorded<'a> = (&'a Renderer, Vec<wgpu::BindGroup>);

/// Records `frames` passes of `draws` into `targets`, the first and last
/// timestamped into `timestamps` where given.
fn record(
    encoder: &mut wgpu::CommandEncoder,
    targets: &Targets,
    draws: &[Recorded],
    clear: [f64; 3],
    frames: u32,
    timestamps: Option<&wgpu::QuerySet>,
) {
    for f in 0..frames {
        let edge = f == 0 || f + 1 == frames;
        let ts = timestamps
            .filter(|_| edge)
            .map(|q| wgpu::RenderPassTimestampWrites {
                query_set: q,
                beginning_of_pass_write_index: (f == 0).then_some(0),
                end_of_pass_write_index: (f + 1 == frames).then_some(1),
            });
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("displace"),
            color_attachments: &[
                cleared_attachment(&targets.color, rgba([clear[0], clear[1], clear[2], 1.0])),
                cleared_attachment(
                    &targets.aov,
                    // No texture coordinate, no hit, no t.
                    rgba([-1.0, -1.0, 0.0, -1.0]),
                ),
            ],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &targets.depth,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: ts,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        for (renderer, groups) in draws {
            pass.set_pipeline(&renderer.pipeline);
            for (k, group) in groups.iter().enumerate() {
                pass.set_bind_group(k as u32, group, &[]);
            }
            match &renderer.kind {
                Kind::Displaced {
                    geometry: Geometry::ShellBox { .. },
                    ..
                } => pass.draw(0..36, 0..1),
                Kind::Displaced {
                    geometry:
                        Geometry::Mesh {
                            vertices, count, ..
                        },
                    ..
                }
                | Kind::Plain {
                    vertices, count, ..
                } => {
                    pass.set_vertex_buffer(0, vertices.slice(..));
                    pass.draw(0..*count, 0..1);
                }
            }
        }
    }
}

/// Draws every `(renderer, draw)` under `view` into one colour, AOV and
/// depth target (the nearest surface wins per pixel, through the fragments'
/// exact depths), cleared to the linear colour `clear`, and reads them
/// back. One view is one projection, so every depth the buffer holds
/// compares; several draws need its [`View::depth_range`]
/// ([`shared_depth_range`]).
pub fn render_faces(
    ctx: &GpuContext,
    view: &View,
    draws: &[(&Renderer, &Draw)],
    clear: [f64; 3],
) -> Result<Image> {
    // Sizes and vectors are checked before the targets are allocated
    // (and once more, for the frame, by `encode_faces`).
    check_frame(view, draws)?;
    Targets::check(ctx, view.size)?;
    let targets = ctx.checked("allocating the frame's targets", || {
        Targets::new(ctx, view.size)
    })?;
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    encode_faces(ctx, &mut encoder, &targets, view, draws, clear)?;
    targets.read(ctx, encoder)
}

/// Records every `(renderer, draw)` under `view` into `targets` on
/// `encoder`, as [`render_faces`] does, without reading anything back (the
/// viewer presents the colour target on the GPU). `targets` must have the
/// view's image size.
pub fn encode_faces(
    ctx: &GpuContext,
    encoder: &mut wgpu::CommandEncoder,
    targets: &Targets,
    view: &View,
    draws: &[(&Renderer, &Draw)],
    clear: [f64; 3],
) -> Result<()> {
    check_frame(view, draws)?;
    if view.size != targets.size {
        return Err(Error::InvalidOption(format!(
            "faces of {:?} pixels drawn into targets of {:?}",
            view.size, targets.size
        )));
    }
    let recorded = draws
        .iter()
        .map(|(r, d)| r.uniforms(ctx, view, d).map(|groups| (*r, groups)))
        .collect::<Result<Vec<_>>>()?;
    ctx.checked("rendering", || {
        record(encoder, targets, &recorded, clear, 1, None)
    })
}

/// The checks of a frame, once for all its draws: the view's, at least one
/// draw, and a positive depth for every displaced one (each draw's face is
/// checked with its renderer's handedness as its uniforms are made).
fn check_frame(view: &View, draws: &[(&Renderer, &Draw)]) -> Result<()> {
    view.check()?;
    if draws.is_empty() {
        return Err(Error::InvalidOption("no faces to render".into()));
    }
    for (r, d) in draws {
        if matches!(r.kind, Kind::Displaced { .. }) {
            d.check_depth()?;
        }
    }
    Ok(())
}

/// Near and far planes that hold the shell boxes of every draw in front of
/// `view`'s camera (`None` when all of them lie behind it), for draws
/// sharing one depth buffer ([`View::depth_range`]).
pub fn shared_depth_range<'a>(
    view: &View,
    draws: impl IntoIterator<Item = &'a Draw>,
) -> Option<[f32; 2]> {
    let forward = view.forward();
    let far = draws
        .into_iter()
        .flat_map(Draw::shell_corners)
        .map(|p| (p - view.eye).dot(forward))
        .fold(0.0f32, f32::max);
    (far > 0.0).then_some([far * 1.01 * 1e-4, far * 1.01])
}

#[cfg(test)]
mod tests {
    use super::super::scene::tests::{draw_of, face, scene};
    use super::*;
    use glam::Vec3;

    /// A view from `eye` looking at `target`.
    fn view(eye: Vec3, target: Vec3) -> View {
        View {
            eye,
            target,
            up: Vec3::Y,
            ..scene().view
        }
    }

    /// A unit face at `origin` in a plane z = const, its shell 0.5 deep.
    fn unit_face(origin: Vec3) -> Draw {
        Draw {
            depth: 0.5,
            ..draw_of(super::super::Face {
                origin,
                tangent: Vec3::X,
                bitangent: Vec3::Y,
                ..face()
            })
        }
    }

    #[test]
    fn no_faces_have_no_range() {
        assert_eq!(shared_depth_range(&scene().view, &[]), None);
    }

    #[test]
    fn the_range_reaches_the_farthest_shell_corner_with_a_margin() {
        // Looking down -z from z = 10: the shell spans z in [0, 0.5], so
        // its farthest corners lie 10 ahead.
        let v = view(Vec3::new(0.0, 0.0, 10.0), Vec3::ZERO);
        let [near, far] = shared_depth_range(&v, &[unit_face(Vec3::ZERO)]).unwrap();
        assert!((far - 10.1).abs() < 1e-4, "{far}");
        assert!((near - 10.1e-4).abs() < 1e-7, "{near}");
    }

    #[test]
    fn every_face_is_measured_along_the_one_camera() {
        let v = view(Vec3::new(0.0, 0.0, 10.0), Vec3::ZERO);
        let deeper = unit_face(Vec3::new(0.0, 0.0, -20.0));
        let [_, far] = shared_depth_range(&v, &[unit_face(Vec3::ZERO), deeper]).unwrap();
        assert!((far - 30.0 * 1.01).abs() < 1e-3, "{far}");
    }

    #[test]
    fn faces_behind_the_camera_have_no_range() {
        let v = view(Vec3::new(0.0, 0.0, 10.0), Vec3::new(0.0, 0.0, 20.0));
        assert_eq!(shared_depth_range(&v, &[unit_face(Vec3::ZERO)]), None);
    }
}
