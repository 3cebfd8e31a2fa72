//! The raster passes: every draw of a frame into one colour, AOV and depth
//! target, the nearest surface winning per pixel through the fragments'
//! exact depths (section 8.5.2's refined hit, written as the fragment's
//! depth), and the checks that faces drawn together share one camera.

use super::pipelines::{Geometry, Kind, Renderer};
use super::targets::{Image, Targets};
use super::PlaneScene;
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
        let groups = self.uniforms(ctx, scene)?;
        let targets = Targets::new(ctx, scene.size);
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
        render_faces(ctx, &[(self, scene)], DEFAULT_CLEAR)
    }
}

/// A clear colour.
fn rgba([r, g, b, a]: [f64; 4]) -> wgpu::Color {
    wgpu::Color { r, g, b, a }
}

/// One draw of a frame: its renderer and bind groups.
type Draw<'a> = (&'a Renderer, Vec<wgpu::BindGroup>);

/// Records `frames` passes of `draws` into `targets`, the first and last
/// timestamped into `timestamps` where given.
fn record(
    encoder: &mut wgpu::CommandEncoder,
    targets: &Targets,
    draws: &[Draw],
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

/// Draws every `(renderer, face)` into one colour, AOV and depth target (the
/// nearest surface wins per pixel, through the fragments' exact depths),
/// cleared to the linear colour `clear`, and reads them back. All faces must
/// share the image size and camera, including [`PlaneScene::depth_range`].
pub fn render_faces(
    ctx: &GpuContext,
    faces: &[(&Renderer, &PlaneScene)],
    clear: [f64; 3],
) -> Result<Image> {
    let first = check_shared_camera(faces)?;
    // Sizes and vectors are checked before anything is allocated.
    for (r, s) in faces {
        s.check()?;
        if matches!(r.kind, Kind::Displaced { .. }) {
            s.check_depth()?;
        }
    }
    let targets = Targets::new(ctx, first.size);
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    encode_faces(ctx, &mut encoder, &targets, faces, clear)?;
    targets.read(ctx, encoder)
}

/// The first face, once every face shares its image size and camera (one
/// depth buffer holds depths of one projection only).
fn check_shared_camera<'a>(faces: &[(&Renderer, &'a PlaneScene)]) -> Result<&'a PlaneScene> {
    let Some((_, first)) = faces.first() else {
        return Err(Error::InvalidOption("no faces to render".into()));
    };
    if faces
        .iter()
        .any(|(_, s)| s.size != first.size || s.view_proj() != first.view_proj())
    {
        return Err(Error::InvalidOption(
            "faces drawn together must share the image size and camera".into(),
        ));
    }
    Ok(first)
}

/// Records the draw of every `(renderer, face)` into `targets` on
/// `encoder`, as [`render_faces`] does, without reading anything back (the
/// viewer presents the colour target on the GPU). `targets` must have the
/// faces' image size.
pub fn encode_faces(
    ctx: &GpuContext,
    encoder: &mut wgpu::CommandEncoder,
    targets: &Targets,
    faces: &[(&Renderer, &PlaneScene)],
    clear: [f64; 3],
) -> Result<()> {
    let first = check_shared_camera(faces)?;
    if first.size != targets.size {
        return Err(Error::InvalidOption(format!(
            "faces of {:?} pixels drawn into targets of {:?}",
            first.size, targets.size
        )));
    }
    let draws = faces
        .iter()
        .map(|(r, s)| r.uniforms(ctx, s).map(|groups| (*r, groups)))
        .collect::<Result<Vec<_>>>()?;
    ctx.checked("rendering", || {
        record(encoder, targets, &draws, clear, 1, None)
    })
}

/// Near and far planes that hold the shell boxes of every face in front of
/// the camera of the first (`None` when all of them lie behind it), for
/// faces drawn into one depth buffer ([`PlaneScene::depth_range`]).
pub fn shared_depth_range(faces: &[PlaneScene]) -> Option<[f32; 2]> {
    let first = faces.first()?;
    let forward = (first.target - first.eye).normalize();
    let far = faces
        .iter()
        .flat_map(PlaneScene::shell_corners)
        .map(|p| (p - first.eye).dot(forward))
        .fold(0.0f32, f32::max);
    (far > 0.0).then_some([far * 1.01 * 1e-4, far * 1.01])
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// A unit face at z = 0, its shell 0.5 deep, seen from `eye` looking
    /// at `target`.
    fn face(eye: Vec3, target: Vec3, origin: Vec3) -> PlaneScene {
        PlaneScene {
            eye,
            target,
            up: Vec3::Y,
            origin,
            tangent: Vec3::X,
            bitangent: Vec3::Y,
            depth: 0.5,
            ..super::super::scene::tests::scene()
        }
    }

    #[test]
    fn no_faces_have_no_range() {
        assert_eq!(shared_depth_range(&[]), None);
    }

    #[test]
    fn the_range_reaches_the_farthest_shell_corner_with_a_margin() {
        // Looking down -z from z = 10: the shell spans z in [0, 0.5], so
        // its farthest corners lie 10 ahead.
        let s = face(Vec3::new(0.0, 0.0, 10.0), Vec3::ZERO, Vec3::ZERO);
        let [near, far] = shared_depth_range(&[s]).unwrap();
        assert!((far - 10.1).abs() < 1e-4, "{far}");
        assert!((near - 10.1e-4).abs() < 1e-7, "{near}");
    }

    #[test]
    fn later_faces_are_measured_along_the_first_camera() {
        let eye = Vec3::new(0.0, 0.0, 10.0);
        let first = face(eye, Vec3::ZERO, Vec3::ZERO);
        // Its own camera would look the other way; the first's is used.
        let deeper = face(
            Vec3::new(0.0, 0.0, -50.0),
            Vec3::ZERO,
            Vec3::new(0.0, 0.0, -20.0),
        );
        let [_, far] = shared_depth_range(&[first, deeper]).unwrap();
        assert!((far - 30.0 * 1.01).abs() < 1e-3, "{far}");
    }

    #[test]
    fn faces_behind_the_camera_have_no_range() {
        let s = face(
            Vec3::new(0.0, 0.0, 10.0),
            Vec3::new(0.0, 0.0, 20.0),
            Vec3::ZERO,
        );
        assert_eq!(shared_depth_range(&[s]), None);
    }
}
