//! The plugin against the CPU's exact trace (`displace-core`) and against
//! `displace gpu-render`'s renderer (displace-gpu), on one displaced quad
//! seen by a pinhole camera (GPU Gems 2 ch. 8, section 8.5):
//! - the displaced texture coordinate the fragment computes agrees with the
//!   exact hit's, and with gpu-render's, on >= 99% of the pixels both
//!   cover;
//! - the two pictures agree: the same checkerboard at the displaced
//!   coordinate, judged by FLIP's mean and 99th percentile;
//! - the depth the prepass holds is the depth of the displaced point;
//! - the shadow map holds the displaced shape: a bump shadows the floor
//!   where the exact trace says it does.
//!
//! On lavapipe in CI. A machine where Bevy finds no adapter fails these
//! tests in CI (`CI` set) and elsewhere unless `DISPLACE_ALLOW_NO_GPU=1`,
//! the policy of displace-gpu's tests.

mod common;
#[path = "common/pictures.rs"]
mod pictures;

use bevy::asset::RenderAssetUsages;
use bevy::camera::{Hdr, RenderTarget};
use bevy::core_pipeline::prepass::DepthPrepass;
use bevy::core_pipeline::schedule::Core3d;
use bevy::core_pipeline::tonemapping::{DebandDither, Tonemapping};
use bevy::core_pipeline::Core3dSystems;
use bevy::image::ImageAddressMode;
use bevy::mesh::{Indices, PrimitiveTopology};
use bevy::prelude::*;
use bevy::render::camera::ExtractedCamera;
use bevy::render::extract_resource::{ExtractResource, ExtractResourcePlugin};
use bevy::render::gpu_readback::{Readback, ReadbackComplete};
use bevy::render::render_asset::RenderAssets;
use bevy::render::render_resource::{
    Extent3d, Origin3d, TexelCopyTextureInfo, TextureAspect, TextureDimension, TextureFormat,
    TextureUsages,
};
use bevy::render::renderer::{RenderContext, ViewQuery};
use bevy::render::texture::GpuImage;
use bevy::render::view::ViewDepthTexture;
use bevy::render::RenderApp;
use displace_bevy::headless::Headless;
use displace_bevy::{DistanceMappedMaterial, DistanceMapping, Encoding, Output};
use displace_core::{Address, DisplacementMap, MapRay, Method, TraceOptions};
use pictures::{checker_image, frame, half, masked_flip};
use std::sync::{Arc, Mutex};

const W: u32 = 192;
const H: u32 = 128;

/// Bevy apps are heavy on two cores: one at a time.
static SERIAL: Mutex<()> = Mutex::new(());

fn map(source: &str) -> DisplacementMap {
    common::baked(source, [64, 64], Address::Clamp, [64, 64, 16], 0.15)
}

/// displace-gpu's built-in plane (`PlaneScene::for_map`, what `displace
/// gpu-render` draws without a scene file): the face spans `[0, sx] x [0,
/// sy]` at z = 0 (the shell's bottom), seen obliquely from above.
struct PlaneScene {
    eye: Vec3,
    target: Vec3,
    up: Vec3,
    fov_y_degrees: f32,
    origin: Vec3,
    tangent: Vec3,
    bitangent: Vec3,
    depth: f32,
    iterations: u32,
}

impl PlaneScene {
    fn for_map(map: &DisplacementMap) -> Self {
        let e = map.extent;
        let centre = Vec3::new(e.sx * 0.5, e.sy * 0.5, 0.0);
        let reach = e.sx.max(e.sy);
        Self {
            eye: centre + Vec3::new(-0.35, -1.0, 0.8) * reach,
            target: centre,
            up: Vec3::Z,
            fov_y_degrees: 45.0,
            origin: Vec3::ZERO,
            tangent: Vec3::new(e.sx, 0.0, 0.0),
            bitangent: Vec3::new(0.0, e.sy, 0.0),
            depth: e.sz,
            iterations: 64,
        }
    }

    fn normal(&self) -> Vec3 {
        self.tangent.cross(self.bitangent).normalize()
    }

    /// World vector to map space (depth units).
    fn to_map(&self, map: &DisplacementMap, v: Vec3) -> Vec3 {
        let [ax, ay] = map.aspect();
        Vec3::new(
            v.dot(self.tangent) / self.tangent.length_squared() * ax,
            v.dot(self.bitangent) / self.bitangent.length_squared() * ay,
            v.dot(self.normal()) / self.depth,
        )
    }

    /// The camera ray through the centre of pixel `(x, y)`, in map space.
    fn pixel_ray(&self, map: &DisplacementMap, x: u32, y: u32) -> MapRay {
        let forward = (self.target - self.eye).normalize();
        let right = forward.cross(self.up).normalize();
        let up = right.cross(forward);
        let tan = (self.fov_y_degrees.to_radians() * 0.5).tan();
        let sx = ((x as f32 + 0.5) / W as f32 * 2.0 - 1.0) * tan * W as f32 / H as f32;
        let sy = (1.0 - (y as f32 + 0.5) / H as f32 * 2.0) * tan;
        let dir = forward + right * sx + up * sy;
        // displace-core's glam is not Bevy's: through arrays.
        MapRay::new(
            self.to_map(map, self.eye - self.origin).to_array().into(),
            self.to_map(map, dir).to_array().into(),
        )
    }

    /// World point of a map-space point.
    fn world(&self, map: &DisplacementMap, p: Vec3) -> Vec3 {
        let [ax, ay] = map.aspect();
        self.origin
            + self.tangent * (p.x / ax)
            + self.bitangent * (p.y / ay)
            + self.normal() * (p.z * self.depth)
    }
}

/// Whether the map-space ray crosses the shell's top face (z = 1 over the
/// face) on its way down: the rays the mesh, which is that face, can
/// start. The others enter through the shell's sides, which displace-gpu
/// draws as a box and the material, like Donnelly's polygon, does not.
fn enters_through_top(map: &DisplacementMap, ray: &MapRay) -> bool {
    let [ax, ay] = map.aspect();
    if ray.dir.z >= 0.0 {
        return false;
    }
    let t = (1.0 - ray.origin.z) / ray.dir.z;
    let p = ray.origin + ray.dir * t;
    (0.0..=ax).contains(&p.x) && (0.0..=ay).contains(&p.y)
}

/// The top of the scene's shell as a Bevy mesh (our material marches down
/// from the mesh; displace-gpu's face is the shell's bottom): texture
/// coordinate (0, 0) at the origin, u along the tangent, v along the
/// bitangent, wound counter-clockwise seen from the normal's side.
fn shell_top(scene: &PlaneScene) -> Mesh {
    let n = scene.normal();
    let o = scene.origin + n * scene.depth;
    let (t, b) = (scene.tangent, scene.bitangent);
    let positions = [o, o + t, o + t + b, o + b];
    Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::RENDER_WORLD,
    )
    .with_inserted_attribute(
        Mesh::ATTRIBUTE_POSITION,
        positions.iter().map(|p| p.to_array()).collect::<Vec<_>>(),
    )
    .with_inserted_attribute(Mesh::ATTRIBUTE_NORMAL, vec![n.to_array(); 4])
    .with_inserted_attribute(
        Mesh::ATTRIBUTE_UV_0,
        vec![[0.0f32, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]],
    )
    .with_inserted_indices(Indices::U32(vec![0, 1, 2, 0, 2, 3]))
}

/// The scene's pinhole camera in Bevy: same eye, target, up and vertical
/// field of view, so pixel (x, y) looks along the same ray.
fn camera(scene: &PlaneScene, target: RenderTarget) -> impl Bundle {
    (
        Camera3d::default(),
        target,
        Projection::Perspective(PerspectiveProjection {
            fov: scene.fov_y_degrees.to_radians(),
            aspect_ratio: W as f32 / H as f32,
            near: 0.01,
            ..default()
        }),
        Transform::from_translation(scene.eye).looking_at(scene.target, scene.up),
        Msaa::Off,
        Tonemapping::None,
        DebandDither::Disabled,
    )
}

/// Spawns the shell's top face into `world` with our material over `base`:
/// the map at the scene's depth and iterations, then `configure`.
fn spawn_displaced(
    world: &mut World,
    map: &DisplacementMap,
    scene: &PlaneScene,
    base: StandardMaterial,
    configure: impl FnOnce(DistanceMapping) -> DistanceMapping,
) {
    let mesh = world.resource_mut::<Assets<Mesh>>().add(shell_top(scene));
    let mapping = {
        let mut images = world.resource_mut::<Assets<Image>>();
        DistanceMapping::from_map(map, Encoding::R8, &mut images).unwrap()
    };
    let material =
        world
            .resource_mut::<Assets<DistanceMappedMaterial>>()
            .add(DistanceMappedMaterial {
                base,
                extension: configure(
                    mapping
                        .with_depth(scene.depth)
                        .with_iterations(scene.iterations),
                ),
            });
    world.spawn((Mesh3d(mesh), MeshMaterial3d(material)));
}

/// Spawns the quad with our material (unlit, or the hit as data) into
/// `app`.
fn spawn_quad(app: &mut Headless, map: &DisplacementMap, scene: &PlaneScene, output: Output) {
    let world = app.world_mut();
    let base = StandardMaterial {
        unlit: true,
        ..default()
    };
    spawn_displaced(world, map, scene, base, |m| m.with_output(output));
    // Alpha 0 where nothing is drawn: a hit writes alpha 1.
    world.insert_resource(ClearColor(Color::linear_rgba(0.02, 0.02, 0.03, 0.0)));
}

#[test]
fn displaced_uv_agrees_with_the_exact_hit() {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let map = map("gen:studded");
    let scene = PlaneScene::for_map(&map);
    let Some(data) = hit_frame(&map, &scene) else {
        return;
    };
    let opts = TraceOptions {
        method: Method::Exact,
        ..Default::default()
    };
    let [ax, ay] = map.aspect();
    let (mut both, mut agree, mut only_bevy, mut only_exact, mut missed) = (0, 0, 0, 0, 0);
    for y in 0..H {
        for x in 0..W {
            let i = (y * W + x) as usize * 8;
            let px = &data[i..i + 8];
            let bevy_hit = half(&px[6..8]) > 0.5;
            let ray = scene.pixel_ray(&map, x, y);
            let exact = map.trace(&ray, &opts);
            match (bevy_hit, exact) {
                (true, Some(h)) => {
                    both += 1;
                    let du = (half(&px[0..2]) - h.position.x / ax).abs();
                    let dv = (half(&px[2..4]) - h.position.y / ay).abs();
                    // Half a height texel (64 texels), well above binary16's
                    // resolution below 1 (2^-11).
                    if du.max(dv) <= 0.5 / 64.0 {
                        agree += 1;
                    }
                }
                (true, None) => only_bevy += 1,
                (false, Some(_)) => {
                    only_exact += 1;
                    missed += usize::from(enters_through_top(&map, &ray));
                }
                (false, None) => {}
            }
        }
    }
    eprintln!("by the exact trace only {only_exact} ({missed} of them entering through the top)");
    // The material draws the mesh (the shell's top face): the trace's own
    // pixels are rays entering through the shell's sides (the strips along
    // the near edges), bar the rasteriser's edge pixels.
    assert_uv_agreement("the exact hit", agree, both, only_bevy);
    assert!(
        missed as f64 <= 0.01 * both as f64,
        "{missed} rays through the top face missed"
    );
}

/// The plugin against `displace gpu-render`'s renderer (displace-gpu's
/// raster path, which draws the face's whole shell box) on the same face,
/// camera and map: the displaced texture coordinate agrees on >= 99% of
/// the pixels both cover, and the plugin covers no pixel the renderer
/// leaves empty.
#[test]
fn displaced_uv_agrees_with_gpu_render() {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let Some(g) = against_gpu_render(hit_frame) else {
        return;
    };
    let data = g.frame;
    let image = g.renderer.render(g.ctx, &g.plane).unwrap();
    let (mut both, mut agree, mut only_bevy, mut only_gpu) = (0usize, 0usize, 0usize, 0usize);
    for y in 0..H {
        for x in 0..W {
            let i = (y * W + x) as usize;
            let px = &data[i * 8..i * 8 + 8];
            let ours = half(&px[6..8]) > 0.5;
            let theirs = image.uv[i];
            match (ours, theirs[2] != 0.0) {
                (true, true) => {
                    both += 1;
                    let du = (half(&px[0..2]) - theirs[0]).abs();
                    let dv = (half(&px[2..4]) - theirs[1]).abs();
                    // Half a height texel (64 texels), as against the
                    // exact hit.
                    agree += usize::from(du.max(dv) <= 0.5 / 64.0);
                }
                (true, false) => only_bevy += 1,
                (false, true) => only_gpu += 1,
                (false, false) => {}
            }
        }
    }
    eprintln!("gpu-render only {only_gpu} (rays through the shell's sides)");
    assert_uv_agreement("gpu-render", agree, both, only_bevy);
}

/// The plugin's quad rendered with the hit as data (`Output::Hit`, a float
/// target: displaced u, v, map-space t and 1 where hit, in binary16), eight
/// bytes a pixel; `None` where the adapter policy allows no GPU.
fn hit_frame(map: &DisplacementMap, scene: &PlaneScene) -> Option<Vec<u8>> {
    let mut app = Headless::new(W, H, TextureFormat::Rgba16Float);
    spawn_quad(&mut app, map, scene, Output::Hit);
    let target = app.target();
    app.world_mut().spawn((camera(scene, target), Hdr));
    let hits = frame(&mut app)?;
    drop(app);
    let data = hits.data.unwrap();
    assert_eq!(data.len(), (W * H * 8) as usize);
    Some(data)
}

/// The uv comparison's verdict against `other`: the face fills a quarter of
/// the frame at least, the plugin's displaced uv agrees on >= 99% of the
/// pixels both cover, and the plugin covers at most 1% more.
fn assert_uv_agreement(other: &str, agree: usize, both: usize, only_bevy: usize) {
    let only = format!("pixels covered by Bevy and not by {other}");
    assert_agreement(
        &format!("displaced uv against {other}"),
        agree,
        both,
        &only,
        only_bevy,
    );
}

/// A comparison's verdict (`what`): the pixels `both` sides cover fill a
/// quarter of the frame at least, `agree` of them (>= 99%) agree, and the
/// `off` pixels (`off_what`: covered by one side only) are at most 1% of
/// `both`.
fn assert_agreement(what: &str, agree: usize, both: usize, off_what: &str, off: usize) {
    let ratio = agree as f64 / both as f64;
    eprintln!(
        "{what}: {agree}/{both} agree ({:.3}%); {off_what}: {off}",
        100.0 * ratio
    );
    assert!(
        both > (W * H / 4) as usize,
        "{what}: both cover {both} pixels"
    );
    assert!(
        ratio >= 0.99,
        "{what}: agrees on {:.3}% of the pixels both cover",
        100.0 * ratio
    );
    assert!(
        off as f64 <= 0.01 * both as f64,
        "{what}: {off_what}: {off}"
    );
}

/// What both comparisons with gpu-render start from: the studded map, the
/// plugin's `frame` of it, and displace-gpu's renderer of the same map
/// (what `displace gpu-render` draws with) with its built-in plane, which
/// is this test's: the same eye, target, field of view, face and depth; the
/// same step budget. `None` where the adapter policy allows no GPU.
struct AgainstGpu<T> {
    frame: T,
    ctx: &'static displace_gpu::GpuContext,
    plane: displace_gpu::PlaneScene,
    renderer: displace_gpu::Renderer,
}

fn against_gpu_render<T>(
    frame: impl FnOnce(&DisplacementMap, &PlaneScene) -> Option<T>,
) -> Option<AgainstGpu<T>> {
    let map = map("gen:studded");
    let scene = PlaneScene::for_map(&map);
    let frame = frame(&map, &scene)?;
    let ctx = displace_gpu::test_support::test_context()?;
    let mut plane = displace_gpu::PlaneScene::for_map(&map, [W, H]);
    plane.draw.iterations = scene.iterations;
    assert_eq!(
        (
            plane.view.eye,
            plane.view.target,
            plane.view.fov_y_degrees,
            plane.draw.depth
        ),
        (scene.eye, scene.target, scene.fov_y_degrees, scene.depth)
    );
    let renderer =
        displace_gpu::Renderer::new(ctx, &map, displace_gpu::DistanceTexture::R8Linear).unwrap();
    Some(AgainstGpu {
        frame,
        ctx,
        plane,
        renderer,
    })
}

/// Mean FLIP allowed over the pixels both renderers cover. Measured on
/// lavapipe (Mesa 22.3): 0.0002 over 9582 pixels; gpu-render's quad drawn
/// 5% shallower gives 0.147, undisplaced (the checker at the shell's top,
/// no parallax) 0.49, so the threshold sits fifty times above the
/// agreement and fifteen times below the nearest wrong picture.
const MEAN_FLIP: f32 = 0.01;
/// 99th-percentile FLIP allowed over the same pixels (rend3's second
/// threshold: an error confined to a few cells, which the mean dilutes).
/// Measured: 0.0034; 5% shallower 0.46, undisplaced 0.87.
const P99_FLIP: f32 = 0.05;

/// The plugin against `displace gpu-render`'s renderer as pictures: the
/// same face, camera and map, both showing displace-gpu's checkerboard
/// (the very texels and mips, sRGB) at the displaced texture coordinate
/// with the undisplaced coordinate's derivatives, compared by FLIP over the
/// pixels both cover. The two light differently (Bevy's PBR against
/// Blinn-Phong), so both show the texture's colour alone: the plugin's
/// material unlit, gpu-render's shading with ambient 1, no light, no
/// specular (`albedo * (ambient + intensity * lit) + specular` is the
/// albedo). Both write 8-bit sRGB targets without tonemapping, so the
/// bytes FLIP reads are the same encoding of linear colour on both sides.
/// The comparison is shown able to fail: gpu-render's quad 5% shallower,
/// and undisplaced, must exceed both thresholds.
#[test]
fn displaced_checker_image_agrees_with_gpu_render() {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let Some(g) = against_gpu_render(checker_frame) else {
        return;
    };
    let (ours, ctx, renderer) = (g.frame, g.ctx, g.renderer);
    let mut plane = g.plane;
    plane.draw.ambient = 1.0;
    plane.view.light_intensity = 0.0;
    plane.draw.specular = 0.0;
    plane.draw.shadows = displace_gpu::Shadows::None;
    // `Renderer::new`'s colour map is `checker_mips(256, 16)`, as ours.
    let theirs = renderer.render(ctx, &plane).unwrap();
    let flip = masked_flip(&ours, &theirs);
    eprintln!(
        "FLIP against gpu-render over {} pixels: mean {:.4} (allowed {MEAN_FLIP}), 99th percentile {:.4} (allowed {P99_FLIP})",
        flip.pixels, flip.mean, flip.p99
    );
    assert!(
        flip.pixels > (W * H / 4) as usize,
        "both cover {} pixels",
        flip.pixels
    );
    if flip.mean > MEAN_FLIP || flip.p99 > P99_FLIP {
        let dir = flip.write("displaced_checker");
        panic!(
            "plugin against gpu-render: mean FLIP {} (allowed {MEAN_FLIP}), 99th percentile {} (allowed {P99_FLIP}); images in {}",
            flip.mean,
            flip.p99,
            dir.display()
        );
    }

    // The controls: the same comparison against gpu-render's quad drawn 5%
    // shallower, and with (almost) no depth (the checker where the
    // undisplaced face has it), fails both thresholds.
    for (what, f) in [
        ("5% shallower", 0.95),
        ("undisplaced", 1e-4 / plane.draw.depth),
    ] {
        let mut wrong = plane;
        wrong.draw.depth = plane.draw.depth * f;
        let c = masked_flip(&ours, &renderer.render(ctx, &wrong).unwrap());
        eprintln!(
            "FLIP against gpu-render's quad {what}: mean {:.4}, 99th percentile {:.4}",
            c.mean, c.p99
        );
        assert!(
            c.mean > MEAN_FLIP && c.p99 > P99_FLIP,
            "the thresholds pass gpu-render's quad {what}: mean {}, 99th percentile {}",
            c.mean,
            c.p99
        );
    }
}

/// The plugin's quad unlit with [`checker_image`] as its base colour
/// texture, in an 8-bit sRGB target (four bytes a pixel, alpha 0 where
/// nothing is drawn); `None` where the adapter policy allows no GPU.
fn checker_frame(map: &DisplacementMap, scene: &PlaneScene) -> Option<Vec<u8>> {
    let mut app = Headless::new(W, H, TextureFormat::Rgba8UnormSrgb);
    {
        let world = app.world_mut();
        let texture = world
            .resource_mut::<Assets<Image>>()
            .add(checker_image(ImageAddressMode::ClampToEdge, usize::MAX));
        let base = StandardMaterial {
            base_color: Color::WHITE,
            base_color_texture: Some(texture),
            unlit: true,
            ..default()
        };
        spawn_displaced(world, map, scene, base, |m| m);
        world.insert_resource(ClearColor(Color::linear_rgba(0.02, 0.02, 0.03, 0.0)));
    }
    let target = app.target();
    app.world_mut().spawn(camera(scene, target));
    let image = frame(&mut app)?;
    assert_eq!(
        image.texture_descriptor.format,
        TextureFormat::Rgba8UnormSrgb
    );
    let data = image.data.unwrap();
    assert_eq!(data.len(), (W * H * 4) as usize);
    Some(data)
}

/// The prepass depth copied out before the main pass, as in Bevy's
/// `render_depth_to_texture` example.
#[derive(Resource, Clone, ExtractResource)]
struct DepthCopy(Handle<Image>);

fn copy_prepass_depth(
    view: ViewQuery<(&ExtractedCamera, &ViewDepthTexture)>,
    copy: Option<Res<DepthCopy>>,
    images: Res<RenderAssets<GpuImage>>,
    mut ctx: RenderContext,
) {
    let Some(copy) = copy else { return };
    let (_, depth) = view.into_inner();
    let Some(dst) = images.get(copy.0.id()) else {
        return;
    };
    ctx.command_encoder().copy_texture_to_texture(
        TexelCopyTextureInfo {
            texture: &depth.texture,
            mip_level: 0,
            origin: Origin3d::default(),
            aspect: TextureAspect::DepthOnly,
        },
        TexelCopyTextureInfo {
            texture: &dst.texture,
            mip_level: 0,
            origin: Origin3d::default(),
            aspect: TextureAspect::DepthOnly,
        },
        Extent3d {
            width: W,
            height: H,
            depth_or_array_layers: 1,
        },
    );
}

#[test]
fn prepass_depth_is_the_depth_of_the_displaced_point() {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let map = map("gen:studded");
    let scene = PlaneScene::for_map(&map);
    let mut app = Headless::with(W, H, TextureFormat::Rgba8UnormSrgb, |app| {
        app.add_plugins(ExtractResourcePlugin::<DepthCopy>::default());
        app.sub_app_mut(RenderApp).add_systems(
            Core3d,
            copy_prepass_depth
                .after(Core3dSystems::Prepass)
                .before(Core3dSystems::MainPass),
        );
    });
    spawn_quad(&mut app, &map, &scene, Output::Shaded);
    let mut depth = Image::new_uninit(
        Extent3d {
            width: W,
            height: H,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        TextureFormat::Depth32Float,
        RenderAssetUsages::RENDER_WORLD,
    );
    depth.texture_descriptor.usage |=
        TextureUsages::COPY_DST | TextureUsages::COPY_SRC | TextureUsages::TEXTURE_BINDING;
    let depth = app.world_mut().resource_mut::<Assets<Image>>().add(depth);
    app.world_mut().insert_resource(DepthCopy(depth.clone()));
    let target = app.target();
    app.world_mut()
        .spawn((camera(&scene, target), DepthPrepass));
    // The first frame, through the adapter policy; then the read-back.
    if frame(&mut app).is_none() {
        return;
    }
    let slot: Arc<Mutex<Option<Vec<u8>>>> = Arc::default();
    let sink = slot.clone();
    app.world_mut()
        .spawn(Readback::texture(depth))
        .observe(move |done: On<ReadbackComplete>| {
            *sink.lock().unwrap() = Some(done.data.clone());
        });
    let mut bytes = None;
    for _ in 0..16 {
        app.update();
        if let Some(b) = slot.lock().unwrap().take() {
            bytes = Some(b);
            break;
        }
    }
    let bytes = bytes.expect("the depth read-back came back");
    assert_eq!(
        bytes.len(),
        (W * H * 4) as usize,
        "rows of {W} f32 are 256-byte aligned"
    );

    // Bevy's reverse-Z infinite perspective: depth = near / view distance
    // along the camera axis.
    let near = 0.01f32;
    let forward = (scene.target - scene.eye).normalize();
    let opts = TraceOptions {
        method: Method::Exact,
        ..Default::default()
    };
    let (mut both, mut close, mut coverage_differs) = (0usize, 0usize, 0usize);
    for y in 0..H {
        for x in 0..W {
            let i = (y * W + x) as usize * 4;
            let d = f32::from_le_bytes(bytes[i..i + 4].try_into().unwrap());
            let ray = scene.pixel_ray(&map, x, y);
            let hit = map.trace(&ray, &opts);
            match (hit, d > 0.0) {
                (Some(hit), true) => {
                    both += 1;
                    let world = scene.world(&map, Vec3::from_array(hit.position.to_array()));
                    let exact = (world - scene.eye).dot(forward);
                    let written = near / d;
                    // In shell depths.
                    if ((written - exact) / scene.depth).abs() <= 1e-3 {
                        close += 1;
                    }
                }
                (None, false) => {}
                // Through the shell's sides: the trace's alone (uv test).
                (Some(_), false) if !enters_through_top(&map, &ray) => {}
                _ => coverage_differs += 1,
            }
        }
    }
    assert_agreement(
        "prepass depth within 1e-3 shell depths",
        close,
        both,
        "pixels whose coverage differs",
        coverage_differs,
    );
}

/// Renders the quad lit white by a low directional light, with or without
/// its shadow map, and returns the sRGB pixels.
fn lit_quad(
    map: &DisplacementMap,
    scene: &PlaneScene,
    to_light: Vec3,
    shadows: bool,
) -> Option<Vec<u8>> {
    use bevy::light::{CascadeShadowConfigBuilder, DirectionalLightShadowMap};
    let mut app = Headless::new(W, H, TextureFormat::Rgba8UnormSrgb);
    {
        let world = app.world_mut();
        let base = StandardMaterial {
            base_color: Color::WHITE,
            perceptual_roughness: 1.0,
            reflectance: 0.0,
            ..default()
        };
        spawn_displaced(world, map, scene, base, |m| m);
        world.insert_resource(GlobalAmbientLight {
            brightness: 0.0,
            ..default()
        });
        world.insert_resource(DirectionalLightShadowMap { size: 2048 });
        world.spawn((
            DirectionalLight {
                illuminance: 10_000.0,
                shadow_maps_enabled: shadows,
                ..default()
            },
            Transform::from_translation(scene.target + to_light).looking_at(scene.target, Vec3::Z),
            CascadeShadowConfigBuilder {
                num_cascades: 1,
                minimum_distance: 0.01,
                maximum_distance: 4.0,
                first_cascade_far_bound: 4.0,
                overlap_proportion: 0.2,
            }
            .build(),
        ));
    }
    let target = app.target();
    app.world_mut().spawn(camera(scene, target));
    frame(&mut app).and_then(|image| image.data)
}

#[test]
fn a_displaced_bump_casts_its_own_shadow() {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    // One tall bump on a flat floor: a flat quad casts no shadow on itself;
    // the displaced one shadows the floor behind the bump.
    let map = map("gen:gaussian");
    let mut scene = PlaneScene::for_map(&map);
    scene.depth = 0.3;
    // Low light from -x: the bump's shadow falls towards +x.
    let to_light = Vec3::new(-1.0, 0.15, 0.45).normalize();
    let Some(lit) = lit_quad(&map, &scene, to_light * 3.0, true) else {
        return;
    };
    let Some(unshadowed) = lit_quad(&map, &scene, to_light * 3.0, false) else {
        return;
    };
    let l_map = scene.to_map(&map, to_light).normalize();
    let opts = TraceOptions {
        method: Method::Exact,
        ..Default::default()
    };
    let luma = |p: &[u8]| p[0] as f32 + p[1] as f32 + p[2] as f32;
    let (mut both, mut agree, mut exact_shadowed, mut bevy_shadowed) = (0, 0, 0, 0);
    for y in 0..H {
        for x in 0..W {
            let i = (y * W + x) as usize * 4;
            let Some(hit) = map.trace(&scene.pixel_ray(&map, x, y), &opts) else {
                continue;
            };
            let off = luma(&unshadowed[i..i + 4]);
            if off < 30.0 {
                // Facing away from the light: shadowed either way.
                continue;
            }
            both += 1;
            let start = hit.position + hit.normal * 1e-3;
            let exact = map.occluded(&MapRay::new(start, l_map.to_array().into()), &opts);
            let bevy = luma(&lit[i..i + 4]) < 0.5 * off;
            exact_shadowed += usize::from(exact);
            bevy_shadowed += usize::from(bevy);
            agree += usize::from(exact == bevy);
        }
    }
    let ratio = agree as f64 / both as f64;
    eprintln!(
        "shadow: {agree}/{both} lit pixels agree ({:.2}%); shadowed: exact {exact_shadowed}, Bevy {bevy_shadowed}",
        100.0 * ratio
    );
    assert!(
        exact_shadowed > 200,
        "the bump shadows {exact_shadowed} pixels"
    );
    assert!(
        bevy_shadowed as f64 > 0.5 * exact_shadowed as f64,
        "the shadow map holds no bump: {bevy_shadowed} shadowed pixels against {exact_shadowed}"
    );
    // A shadow map's texels, filter and biases blur the edge.
    assert!(
        ratio >= 0.9,
        "shadowed where the exact trace says on {:.2}%",
        100.0 * ratio
    );
}
