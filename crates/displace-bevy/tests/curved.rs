//! The curved material ([`CurvedMappedMaterial`]) against `displace
//! gpu-render`'s curved raster path (displace-gpu's `curved.wgsl`, the
//! CPU renderer's shells walked per fragment) on the built-in sphere and
//! torus, each seen by the same pinhole camera:
//! - hit or miss agrees, and the hit's texture coordinate (within half a
//!   height texel) and distance from the eye agree, on >= 99% of the
//!   pixels;
//! - the pictures agree (displace-gpu's checkerboard at the hit, unlit),
//!   by FLIP's mean and 99th percentile, with the flat material's
//!   thresholds; a shallower gpu-render sphere fails them;
//! - on a smooth height field the normals show no seam (lines of broken
//!   normals, or lone pixels of the far side through a hole);
//! - an orthographic view (the shadow maps' path, where the walk starts
//!   behind the fragment) covers the displaced sphere's disc.
//!
//! The torus is drawn with a Bevy `Transform` (turned and moved) against
//! gpu-render's triangles moved alike, so the material's walk in the mesh's
//! own space is checked too. On lavapipe in CI, with the adapter policy of
//! `render.rs`.

mod common;
#[path = "common/pictures.rs"]
mod pictures;

use bevy::camera::{Hdr, RenderTarget};
use bevy::core_pipeline::tonemapping::{DebandDither, Tonemapping};
use bevy::image::ImageAddressMode;
use bevy::mesh::PrimitiveTopology;
use bevy::prelude::*;
use bevy::render::render_resource::TextureFormat;
use bevy::render::storage::ShaderBuffer;
use displace_bevy::headless::Headless;
use displace_bevy::{CurvedMappedMaterial, CurvedShellMesh, Encoding, Output};
use displace_core::{Address, DisplacementMap, Method};
use displace_gpu::raster::{render_faces, shared_depth_range};
use displace_gpu::{CurvedShells, DistanceTexture, Draw, DrawShape, Renderer, Shadows, View};
use displace_scene::mesh::MeshTriangle;
use displace_scene::mesh_shells::MeshShells;
use pictures::{checker_image, frame, half, masked_flip};
use std::sync::Mutex;

const W: u32 = 256;
const H: u32 = 192;

/// Bevy apps are heavy on two cores: one at a time.
static SERIAL: Mutex<()> = Mutex::new(());

/// A built-in mesh, displaced, placed and seen: what both renderers draw.
struct Curved {
    /// The mesh's own triangles, texture coordinates in `[0, 1]`.
    local: Vec<MeshTriangle>,
    /// Tiles of the map over the texture square.
    tiles: [f32; 2],
    /// Turn (about y, degrees) and move of the object.
    turn_degrees: f32,
    offset: Vec3,
    depth: f32,
    map: DisplacementMap,
    eye: Vec3,
    target: Vec3,
    fov_y_degrees: f32,
}

impl Curved {
    fn new(name: &str, height: &str, height_size: usize) -> Self {
        let local = displace_scene::builtin_mesh::generate(name)
            .unwrap()
            .triangles;
        let map = common::baked(
            height,
            [height_size, height_size],
            Address::Repeat,
            [64, 64, 8],
            0.1,
        );
        match name {
            "sphere" => Self {
                local,
                tiles: [2.0, 1.0],
                turn_degrees: 0.0,
                offset: Vec3::ZERO,
                depth: 0.08,
                map,
                eye: Vec3::new(0.3, 1.2, -3.5),
                target: Vec3::ZERO,
                fov_y_degrees: 36.0,
            },
            _ => Self {
                local,
                tiles: [6.0, 2.0],
                turn_degrees: 25.0,
                offset: Vec3::new(0.2, -0.1, 0.3),
                depth: 0.05,
                map,
                eye: Vec3::new(0.2, 2.3, -2.6),
                target: Vec3::new(0.2, -0.1, 0.3),
                fov_y_degrees: 45.0,
            },
        }
    }

    fn transform(&self) -> Transform {
        Transform::from_translation(self.offset)
            .with_rotation(Quat::from_rotation_y(self.turn_degrees.to_radians()))
    }

    /// The triangles in world space with texture coordinates in tiles,
    /// as a scene hands them to displace-gpu (displace-scene's glam is not
    /// Bevy's: through arrays).
    fn world(&self) -> Vec<MeshTriangle> {
        let m = self.transform().to_matrix();
        let p = |v: glam::Vec3| {
            glam::Vec3::from_array(
                m.transform_point3(Vec3::from_array(v.to_array()))
                    .to_array(),
            )
        };
        let n = |v: glam::Vec3| {
            glam::Vec3::from_array(
                m.transform_vector3(Vec3::from_array(v.to_array()))
                    .to_array(),
            )
        };
        let tiles = glam::Vec2::from_array(self.tiles);
        self.local
            .iter()
            .map(|t| MeshTriangle {
                positions: t.positions.map(p),
                normals: t.normals.map(|ns| ns.map(n)),
                uvs: t.uvs.map(|uv| uv * tiles),
            })
            .collect()
    }

    /// The mesh's own triangles as a Bevy mesh, unindexed.
    fn bevy_mesh(&self) -> Mesh {
        let mut positions = Vec::new();
        let mut normals = Vec::new();
        let mut uvs = Vec::new();
        for t in &self.local {
            let ns = t.normals.expect("built-in meshes have normals");
            for ((p, n), uv) in t.positions.iter().zip(ns).zip(t.uvs) {
                positions.push(p.to_array());
                normals.push(n.to_array());
                uvs.push(uv.to_array());
            }
        }
        Mesh::new(
            PrimitiveTopology::TriangleList,
            bevy::asset::RenderAssetUsages::RENDER_WORLD,
        )
        .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions)
        .with_inserted_attribute(Mesh::ATTRIBUTE_NORMAL, normals)
        .with_inserted_attribute(Mesh::ATTRIBUTE_UV_0, uvs)
    }

    /// The pinhole camera gpu-render's view has.
    fn perspective(&self) -> Projection {
        Projection::Perspective(PerspectiveProjection {
            fov: self.fov_y_degrees.to_radians(),
            aspect_ratio: W as f32 / H as f32,
            near: 0.01,
            ..default()
        })
    }

    fn camera(&self, target: RenderTarget, projection: Projection) -> impl Bundle {
        (
            Camera3d::default(),
            target,
            projection,
            Transform::from_translation(self.eye).looking_at(self.target, Vec3::Y),
            Msaa::Off,
            Tonemapping::None,
            DebandDither::Disabled,
        )
    }

    /// Bevy's frame of the object with the curved material over `base`
    /// (its output `output`) in a target of `format`.
    fn bevy_frame(
        &self,
        base: impl FnOnce(&mut World) -> StandardMaterial,
        output: Output,
        format: TextureFormat,
    ) -> Option<Vec<u8>> {
        self.bevy_frame_with(base, output, format, self.perspective())
    }

    /// [`Curved::bevy_frame`] through `projection`.
    fn bevy_frame_with(
        &self,
        base: impl FnOnce(&mut World) -> StandardMaterial,
        output: Output,
        format: TextureFormat,
        projection: Projection,
    ) -> Option<Vec<u8>> {
        let mut app = Headless::new(W, H, format);
        {
            let world = app.world_mut();
            let source = self.bevy_mesh();
            let shells = world.resource_scope(|world, mut images: Mut<Assets<Image>>| {
                let mut buffers = world.resource_mut::<Assets<ShaderBuffer>>();
                CurvedShellMesh::new(
                    &source,
                    Vec2::from_array(self.tiles),
                    &self.map,
                    self.depth,
                    Encoding::R8,
                    &mut images,
                    &mut buffers,
                )
                .unwrap()
            });
            let base = base(world);
            let mesh = world.resource_mut::<Assets<Mesh>>().add(shells.mesh);
            let material =
                world
                    .resource_mut::<Assets<CurvedMappedMaterial>>()
                    .add(CurvedMappedMaterial {
                        base,
                        extension: shells.mapping.with_output(output),
                    });
            world.spawn((Mesh3d(mesh), MeshMaterial3d(material), self.transform()));
            world.insert_resource(ClearColor(Color::linear_rgba(0.02, 0.02, 0.03, 0.0)));
        }
        let target = app.target();
        let camera = self.camera(target, projection);
        if format == TextureFormat::Rgba16Float {
            app.world_mut().spawn((camera, Hdr));
        } else {
            app.world_mut().spawn(camera);
        }
        let image = frame(&mut app)?;
        image.data
    }

    /// displace-gpu's curved draw of the same object (shells of the world
    /// triangles, displaced `depth_factor` times as deep) under the same
    /// camera, unlit: its checkerboard at the hit.
    fn gpu_image(&self, depth_factor: f32) -> Option<displace_gpu::Image> {
        let ctx = displace_gpu::test_support::test_context()?;
        let triangles = self.world();
        let depth = self.depth * depth_factor;
        let address = self.map.distance.address();
        let shells = MeshShells::of(&triangles, depth, address);
        let curved = CurvedShells::new(&triangles, &shells, depth, self.map.aspect(), address)
            .unwrap()
            .expect("the built-in mesh is curved");
        let renderer =
            Renderer::checker_curved(ctx, &self.map, DistanceTexture::R8Linear, &curved).unwrap();
        let to_gpu = |v: Vec3| glam::Vec3::from_array(v.to_array());
        let draw = Draw {
            shape: DrawShape::Mesh {
                bounds: curved.bounds,
            },
            depth,
            method: Method::Sphere,
            iterations: 64,
            shadows: Shadows::None,
            penumbra_k: 8.0,
            ambient: 1.0,
            albedo_scale: 1.0,
            specular: 0.0,
            shininess: 32.0,
        };
        let mut view = View {
            size: [W, H],
            eye: to_gpu(self.eye),
            target: to_gpu(self.target),
            up: glam::Vec3::Y,
            fov_y_degrees: self.fov_y_degrees,
            depth_range: None,
            light: to_gpu(self.eye),
            light_intensity: 0.0,
            falloff: false,
        };
        view.depth_range = shared_depth_range(&view, [&draw]);
        Some(render_faces(ctx, &view, &[(&renderer, &draw)], [0.02, 0.02, 0.03]).unwrap())
    }
}

/// The verdict of a comparison of coverage and texture coordinates.
fn hits_agree(what: &str, bevy: &[u8], gpu: &displace_gpu::Image, texels: f32) {
    let (mut both, mut agree, mut only_bevy, mut only_gpu) = (0usize, 0usize, 0usize, 0usize);
    for i in 0..(W * H) as usize {
        let px = &bevy[i * 8..i * 8 + 8];
        let ours = half(&px[6..8]) > 0.5;
        let theirs = gpu.uv[i];
        match (ours, theirs[2] != 0.0) {
            (true, true) => {
                both += 1;
                let du = (half(&px[0..2]) - theirs[0]).abs();
                let dv = (half(&px[2..4]) - theirs[1]).abs();
                // Half a height texel, in tiles; the distance to the hit
                // (the depth both write) within binary16's rounding.
                let dt = (half(&px[4..6]) - theirs[3]).abs();
                agree += usize::from(du.max(dv) <= 0.5 / texels && dt <= 2e-3 * (1.0 + theirs[3]));
            }
            (true, false) => only_bevy += 1,
            (false, true) => only_gpu += 1,
            (false, false) => {}
        }
    }
    let ratio = agree as f64 / both as f64;
    eprintln!(
        "{what}: {agree}/{both} texture coordinates and distances agree ({:.3}%); Bevy only {only_bevy}, gpu-render only {only_gpu}",
        100.0 * ratio
    );
    assert!(
        both > (W * H / 5) as usize,
        "{what}: both cover {both} pixels"
    );
    assert!(ratio >= 0.99, "{what}: {:.3}% agree", 100.0 * ratio);
    assert!(
        (only_bevy + only_gpu) as f64 <= 0.01 * both as f64,
        "{what}: hit or miss differs on {} pixels",
        only_bevy + only_gpu
    );
}

fn unlit(_: &mut World) -> StandardMaterial {
    StandardMaterial {
        unlit: true,
        ..default()
    }
}

#[test]
fn curved_hits_agree_with_gpu_render() {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    for name in ["sphere", "torus"] {
        let scene = Curved::new(name, "gen:noise?octaves=4&frequency=4", 128);
        let Some(bevy) = scene.bevy_frame(unlit, Output::Hit, TextureFormat::Rgba16Float) else {
            return;
        };
        let gpu = scene
            .gpu_image(1.0)
            .expect("a frame from Bevy, so an adapter");
        hits_agree(name, &bevy, &gpu, 128.0);
    }
}

/// Mean FLIP allowed over the pixels both renderers cover: the flat
/// material's thresholds (render.rs), which sit far below a wrong picture.
const MEAN_FLIP: f32 = 0.01;
/// 99th-percentile FLIP allowed over the same pixels.
const P99_FLIP: f32 = 0.05;

#[test]
fn curved_checker_image_agrees_with_gpu_render() {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    for name in ["sphere", "torus"] {
        let scene = Curved::new(name, "gen:noise?octaves=4&frequency=4", 128);
        let checker = |world: &mut World| {
            // Level 0 only: displace-gpu's curved draw reads no mips.
            let image = checker_image(ImageAddressMode::Repeat, 1);
            let texture = world.resource_mut::<Assets<Image>>().add(image);
            StandardMaterial {
                base_color: Color::WHITE,
                base_color_texture: Some(texture),
                unlit: true,
                ..default()
            }
        };
        let Some(ours) = scene.bevy_frame(checker, Output::Shaded, TextureFormat::Rgba8UnormSrgb)
        else {
            return;
        };
        let theirs = scene.gpu_image(1.0).expect("an adapter");
        let flip = masked_flip(&ours, &theirs);
        eprintln!(
            "{name}: FLIP against gpu-render over {} pixels: mean {:.4} (allowed {MEAN_FLIP}), 99th percentile {:.4} (allowed {P99_FLIP})",
            flip.pixels, flip.mean, flip.p99
        );
        assert!(
            flip.pixels > (W * H / 5) as usize,
            "{name}: {} pixels",
            flip.pixels
        );
        if flip.mean > MEAN_FLIP || flip.p99 > P99_FLIP {
            let dir = flip.write(&format!("curved_checker_{name}"));
            panic!(
                "{name}: mean FLIP {} (allowed {MEAN_FLIP}), 99th percentile {} (allowed {P99_FLIP}); images in {}",
                flip.mean,
                flip.p99,
                dir.display()
            );
        }
        // The control: gpu-render's object 30% shallower fails both.
        let wrong = masked_flip(&ours, &scene.gpu_image(0.7).unwrap());
        eprintln!(
            "{name}: FLIP against gpu-render 30% shallower: mean {:.4}, 99th percentile {:.4}",
            wrong.mean, wrong.p99
        );
        assert!(
            wrong.mean > MEAN_FLIP && wrong.p99 > P99_FLIP,
            "{name}: the thresholds pass a shallower object: mean {}, 99th percentile {}",
            wrong.mean,
            wrong.p99
        );
    }
}

/// Pixels whose normal breaks (by more than 20 degrees) against both
/// horizontal (or both vertical) neighbours while those two agree: a line
/// across a smooth surface, the seam a shell's wall or a flat shell's edge
/// draws (the measure of displace-render's curved tests).
fn seams(rgba8: &[u8]) -> usize {
    let normal = |x: u32, y: u32| -> Option<Vec3> {
        let i = ((y * W + x) * 4) as usize;
        let px = &rgba8[i..i + 4];
        (px[3] > 127).then(|| {
            (Vec3::new(px[0] as f32, px[1] as f32, px[2] as f32) / 255.0 * 2.0 - Vec3::ONE)
                .normalize_or_zero()
        })
    };
    let break_ = |a: Vec3, b: Vec3| a.dot(b) < 20f32.to_radians().cos();
    let mut count = 0;
    for y in 1..H - 1 {
        for x in 1..W - 1 {
            let Some(c) = normal(x, y) else { continue };
            for (a, b) in [
                (normal(x - 1, y), normal(x + 1, y)),
                (normal(x, y - 1), normal(x, y + 1)),
            ] {
                if let (Some(a), Some(b)) = (a, b) {
                    if break_(c, a) && break_(c, b) && !break_(a, b) {
                        count += 1;
                    }
                }
            }
        }
    }
    count
}

#[test]
fn smooth_heights_show_no_seams_on_curved_shells() {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    for name in ["sphere", "torus"] {
        let scene = Curved::new(name, "gen:flat?level=0.6", 16);
        // Linear normals in an 8-bit target: no sRGB curve on the data.
        let Some(normals) = scene.bevy_frame(unlit, Output::Normal, TextureFormat::Rgba8Unorm)
        else {
            return;
        };
        let found = seams(&normals);
        eprintln!("{name}: {found} seam pixels with the curved material");
        if found > 0 {
            let path = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
                .join(format!("curved_normals_{name}.png"));
            image::RgbaImage::from_raw(W, H, normals)
                .unwrap()
                .save(&path)
                .unwrap();
            panic!("{name}: {found} seam pixels; normals in {}", path.display());
        }
    }
}

/// The measure's control: a smooth field of normals with one column of
/// broken ones (a wall's line) counts that line, and the field without it
/// counts nothing. (The curved walk's own failure, found by this test,
/// was lone pixels of the far side's base showing through holes at the
/// edges between tops: each counts twice.)
#[test]
fn the_seam_measure_sees_a_line() {
    let field = |line: bool| -> Vec<u8> {
        (0..W * H)
            .flat_map(|i| {
                let (x, y) = (i % W, i / W);
                let n = if line && x == W / 2 && (20..120).contains(&y) {
                    Vec3::new(1.0, 0.0, 0.3)
                } else {
                    Vec3::new(x as f32 / W as f32 - 0.5, y as f32 / H as f32 - 0.5, 1.0)
                }
                .normalize();
                let c = (n * 0.5 + Vec3::splat(0.5)) * 255.0;
                [c.x as u8, c.y as u8, c.z as u8, 255]
            })
            .collect()
    };
    assert_eq!(seams(&field(false)), 0);
    assert!(seams(&field(true)) >= 100);
}

/// An orthographic view (the view of a directional light's shadow map,
/// where the walk starts behind the fragment: `CurvedMappingSettings::reach`)
/// of the sphere displaced on a flat field: the surface lies 0.6 of the
/// depth out along the vertex normals, a sphere of radius `1 + 0.6 depth`
/// to within the base mesh's chords (0.2%), so the pixels hit cover its
/// disc. The undisplaced sphere's disc is 9% smaller.
#[test]
fn an_orthographic_view_sees_the_displaced_silhouette() {
    use bevy::camera::ScalingMode;
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let scene = Curved::new("sphere", "gen:flat?level=0.6", 16);
    let height = 2.6;
    let projection = Projection::Orthographic(OrthographicProjection {
        scaling_mode: ScalingMode::Fixed {
            width: height * W as f32 / H as f32,
            height,
        },
        ..OrthographicProjection::default_3d()
    });
    let Some(hits) =
        scene.bevy_frame_with(unlit, Output::Hit, TextureFormat::Rgba16Float, projection)
    else {
        return;
    };
    let covered = (0..(W * H) as usize)
        .filter(|i| half(&hits[i * 8 + 6..i * 8 + 8]) > 0.5)
        .count();
    let pixel = (height / H as f32).powi(2);
    let radius = 1.0 + 0.6 * scene.depth;
    let ratio = covered as f32 * pixel / (std::f32::consts::PI * radius * radius);
    eprintln!("orthographic: {covered} pixels, {ratio:.4} of the displaced sphere's disc");
    assert!((ratio - 1.0).abs() <= 0.02, "covered {ratio} of the disc");
}
