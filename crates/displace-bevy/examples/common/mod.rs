//! The scene both examples draw: a displaced stone floor (Donnelly's
//! figure 8-1 surface, GPU Gems 2 ch. 8), a displaced sphere and torus
//! drawn through their curved shells (`CurvedMappedMaterial`: the surface
//! along the interpolated vertex normals, no facets, seams or pinched
//! poles) under a point light that casts shadows, with the same height map
//! also set up as Bevy's own parallax mapping for the `stone` example's
//! comparison.

use bevy::math::Affine2;
use bevy::prelude::*;
use bevy::render::storage::ShaderBuffer;
use displace_bevy::{
    CurvedMappedMaterial, CurvedShellMesh, DistanceMappedMaterial, DistanceMapping, Encoding,
};
use displace_core::BakeOptions;
use displace_core::{Address, Extent};

/// Height source: tiling fractal noise, as `scenes/stone.toml`.
pub const HEIGHT: &str = "gen:noise?octaves=6&frequency=4";

/// World depth of the floor's shell and of the sphere's.
pub const FLOOR_DEPTH: f32 = 0.15;
pub const SPHERE_DEPTH: f32 = 0.04;
/// Displacement depth of the curved torus, in its mesh's units.
pub const TORUS_DEPTH: f32 = 0.05;

/// The floor, the sphere and the torus, with the materials and meshes the
/// `stone` example switches between.
pub struct Stone {
    pub floor: Entity,
    pub sphere: Entity,
    pub floor_material: Handle<DistanceMappedMaterial>,
    /// The sphere through its curved shells.
    pub sphere_material: Handle<CurvedMappedMaterial>,
    /// The shells' boundary, which the curved material draws.
    pub sphere_shells: Handle<Mesh>,
    /// Bevy's UV sphere itself, which Bevy's parallax mapping draws.
    pub sphere_mesh: Handle<Mesh>,
    /// The height map as an 8-bit image for Bevy's `StandardMaterial::depth_map`
    /// (1 - height: Bevy's depth maps push in where ours are low).
    pub bevy_depth_map: Handle<Image>,
}

/// Bakes the map (a second or two) and spawns floor, sphere, torus and
/// light.
pub fn spawn(world: &mut World) -> Stone {
    let opts = BakeOptions {
        size: [128, 128, 16],
        extent: Extent {
            sx: 1.0,
            sy: 1.0,
            sz: 0.1,
        },
        ..Default::default()
    };
    let (floor_mapping, depth_image, albedo, map) = {
        let mut images = world.resource_mut::<Assets<Image>>();
        let height_opts = displace_core::io::height::HeightOptions {
            address: Address::Repeat,
            ..Default::default()
        };
        let height =
            displace_core::io::height::load(HEIGHT, &height_opts).expect("built-in height");
        let map = displace_core::bake(&height, &opts).expect("bake");
        let mapping = DistanceMapping::from_map(&map, Encoding::R8, &mut images).expect("upload");
        let depth_image = bevy_depth_map(&height);
        let albedo = images.add(albedo_map(&height));
        (
            mapping.with_depth(FLOOR_DEPTH),
            images.add(depth_image),
            albedo,
            map,
        )
    };
    let floor_mesh = world
        .resource_mut::<Assets<Mesh>>()
        .add(Plane3d::default().mesh().size(4.0, 4.0));
    let stone = StandardMaterial {
        base_color: Color::srgb(0.55, 0.5, 0.45),
        base_color_texture: Some(albedo.clone()),
        perceptual_roughness: 0.8,
        uv_transform: Affine2::from_scale(Vec2::splat(2.0)),
        ..default()
    };
    let floor_material =
        world
            .resource_mut::<Assets<DistanceMappedMaterial>>()
            .add(DistanceMappedMaterial {
                base: stone.clone(),
                extension: floor_mapping,
            });
    let floor = world
        .spawn((Mesh3d(floor_mesh), MeshMaterial3d(floor_material.clone())))
        .id();

    // The sphere and the torus: Bevy's own meshes, displaced along their
    // vertex normals through curved shells; the texture coordinate of
    // their base materials is the hit's, in tiles of the map.
    let curved_base = StandardMaterial {
        uv_transform: Affine2::IDENTITY,
        ..stone
    };
    let sphere_source = Sphere::new(0.6).mesh().uv(64, 32);
    let (sphere_shells, sphere_material) = curved(
        world,
        &sphere_source,
        Vec2::new(4.0, 2.0),
        &map,
        SPHERE_DEPTH,
        StandardMaterial {
            base_color: Color::srgb(0.6, 0.55, 0.5),
            ..curved_base.clone()
        },
    );
    let sphere_mesh = world.resource_mut::<Assets<Mesh>>().add(sphere_source);
    let sphere = world
        .spawn((
            Mesh3d(sphere_shells.clone()),
            MeshMaterial3d(sphere_material.clone()),
            // Bevy's UV sphere has its poles on z, where the texture
            // square pinches to a point: turned to put them on y, away
            // from the camera.
            Transform::from_xyz(0.4, 0.6, 0.5)
                .with_rotation(Quat::from_rotation_x(std::f32::consts::FRAC_PI_2)),
        ))
        .id();
    let (torus_shells, torus_material) = curved(
        world,
        &Torus::new(0.25, 0.55).mesh().build(),
        Vec2::new(6.0, 2.0),
        &map,
        TORUS_DEPTH,
        StandardMaterial {
            base_color: Color::srgb(0.8, 0.55, 0.4),
            perceptual_roughness: 0.6,
            ..curved_base
        },
    );
    world.spawn((
        Mesh3d(torus_shells),
        MeshMaterial3d(torus_material),
        Transform::from_xyz(-1.0, 0.45, 0.7).with_rotation(Quat::from_rotation_x(-0.7)),
    ));
    world.spawn((
        PointLight {
            intensity: 2.0e6,
            range: 40.0,
            shadow_maps_enabled: true,
            ..default()
        },
        Transform::from_xyz(2.0, 3.0, -3.0),
    ));
    world.insert_resource(GlobalAmbientLight {
        brightness: 150.0,
        ..default()
    });
    Stone {
        floor,
        sphere,
        floor_material,
        sphere_material,
        sphere_shells,
        sphere_mesh,
        bevy_depth_map: depth_image,
    }
}

/// The curved shells of `source` displaced `depth` deep by `map` (its
/// texture square `tiles` tiles of the map): the mesh to draw and its
/// material over `base`.
fn curved(
    world: &mut World,
    source: &Mesh,
    tiles: Vec2,
    map: &displace_core::DisplacementMap,
    depth: f32,
    base: StandardMaterial,
) -> (Handle<Mesh>, Handle<CurvedMappedMaterial>) {
    let shells = world.resource_scope(|world, mut images: Mut<Assets<Image>>| {
        let mut buffers = world.resource_mut::<Assets<ShaderBuffer>>();
        CurvedShellMesh::new(
            source,
            tiles,
            map,
            depth,
            Encoding::R8,
            &mut images,
            &mut buffers,
        )
        .expect("Bevy's meshes have normals and texture coordinates")
    });
    let mesh = world.resource_mut::<Assets<Mesh>>().add(shells.mesh);
    let material = world
        .resource_mut::<Assets<CurvedMappedMaterial>>()
        .add(CurvedMappedMaterial {
            base,
            extension: shells.mapping,
        });
    (mesh, material)
}

/// Bevy's own parallax mapping of the same height map at the same depths,
/// as `StandardMaterial`s for floor and sphere (the comparison of the
/// `stone` example and of BENCHMARKS.md): adds the tangents it needs to the
/// meshes (ours derives its frame from screen-space derivatives).
pub fn bevy_parallax(
    world: &mut World,
    stone: &Stone,
    method: bevy::pbr::ParallaxMappingMethod,
) -> [Handle<StandardMaterial>; 2] {
    let floor_mesh = world.get::<Mesh3d>(stone.floor).expect("a mesh").0.clone();
    for handle in [floor_mesh, stone.sphere_mesh.clone()] {
        if let Some(mut mesh) = world.resource_mut::<Assets<Mesh>>().get_mut(&handle) {
            if !mesh.contains_attribute(Mesh::ATTRIBUTE_TANGENT) {
                mesh.generate_tangents()
                    .expect("meshes with normals and UVs");
            }
        }
    }
    let floor_base = world
        .resource::<Assets<DistanceMappedMaterial>>()
        .get(&stone.floor_material)
        .expect("floor")
        .base
        .clone();
    let sphere_base = StandardMaterial {
        // Bevy's parallax tiles the map over the sphere by the texture
        // transform; ours by the shells' texture scale.
        uv_transform: Affine2::from_scale(Vec2::new(4.0, 2.0)),
        ..world
            .resource::<Assets<CurvedMappedMaterial>>()
            .get(&stone.sphere_material)
            .expect("sphere")
            .base
            .clone()
    };
    // Bevy's depth scale is in units of the texture coordinate: the world
    // depth over the world size of one tile (4 m floor, 3.8 m sphere
    // circumference, each over its uv_transform scale).
    let parallax = |base: StandardMaterial, depth: f32, size: f32| StandardMaterial {
        depth_map: Some(stone.bevy_depth_map.clone()),
        parallax_depth_scale: depth / (size / base.uv_transform.matrix2.x_axis.x),
        max_parallax_layer_count: 16.0,
        parallax_mapping_method: method,
        ..base
    };
    let mut materials = world.resource_mut::<Assets<StandardMaterial>>();
    [
        materials.add(parallax(floor_base, FLOOR_DEPTH, 4.0)),
        materials.add(parallax(
            sphere_base,
            SPHERE_DEPTH,
            2.0 * std::f32::consts::PI * 0.6,
        )),
    ]
}

/// Puts Bevy's parallax materials on floor and sphere in place of ours
/// (the sphere's own mesh in place of its shells).
pub fn show_bevy(world: &mut World, stone: &Stone, materials: &[Handle<StandardMaterial>; 2]) {
    world
        .entity_mut(stone.floor)
        .remove::<MeshMaterial3d<DistanceMappedMaterial>>()
        .insert(MeshMaterial3d(materials[0].clone()));
    world
        .entity_mut(stone.sphere)
        .remove::<MeshMaterial3d<CurvedMappedMaterial>>()
        .insert((
            Mesh3d(stone.sphere_mesh.clone()),
            MeshMaterial3d(materials[1].clone()),
        ));
}

/// Puts our materials back on floor and sphere.
pub fn show_ours(world: &mut World, stone: &Stone) {
    world
        .entity_mut(stone.floor)
        .remove::<MeshMaterial3d<StandardMaterial>>()
        .insert(MeshMaterial3d(stone.floor_material.clone()));
    world
        .entity_mut(stone.sphere)
        .remove::<MeshMaterial3d<StandardMaterial>>()
        .insert((
            Mesh3d(stone.sphere_shells.clone()),
            MeshMaterial3d(stone.sphere_material.clone()),
        ));
}

/// The camera of `scenes/stone.toml`.
pub fn camera_transform() -> Transform {
    Transform::from_xyz(0.0, 2.2, -3.2).looking_at(Vec3::new(0.0, 0.0, 0.3), Vec3::Y)
}

/// A colour map from the heights (darker in the hollows), so that every
/// method's displaced texture coordinate shows in the picture (and Bevy's
/// parallax loop is not optimised away for want of a texture to read).
fn albedo_map(height: &displace_core::HeightMap) -> Image {
    use bevy::render::render_resource::TextureFormat;
    repeating_image(height, TextureFormat::Rgba8UnormSrgb, |h| {
        let g = ((0.45 + 0.55 * h) * 255.0).round() as u8;
        vec![g, g, g, 255]
    })
}

/// Bevy's parallax mapping reads a depth map (white = deepest).
fn bevy_depth_map(height: &displace_core::HeightMap) -> Image {
    use bevy::render::render_resource::TextureFormat;
    repeating_image(height, TextureFormat::R8Unorm, |h| {
        vec![((1.0 - h) * 255.0).round() as u8]
    })
}

/// One texel of `format` per height texel (heights clamped to [0, 1]),
/// sampled linearly and repeating, as the map tiles.
fn repeating_image(
    height: &displace_core::HeightMap,
    format: bevy::render::render_resource::TextureFormat,
    texel: impl Fn(f32) -> Vec<u8>,
) -> Image {
    use bevy::image::{ImageAddressMode, ImageSampler, ImageSamplerDescriptor};
    let mut image = displace_bevy::texel_image(height, format, |h| texel(h.clamp(0.0, 1.0)));
    image.sampler = ImageSampler::Descriptor(ImageSamplerDescriptor {
        address_mode_u: ImageAddressMode::Repeat,
        address_mode_v: ImageAddressMode::Repeat,
        ..ImageSamplerDescriptor::linear()
    });
    image
}
