//! Our KTX2 (displace-core's writer, what `displace bake` writes) through
//! Bevy's own image loader: a 3D texture of the expected format and size
//! whose texels are the ones the material uploads from a bake; malformed
//! files are Bevy's load error (and ours), never a panic. No GPU needed:
//! the loader is Bevy's `ImageLoader`, registered as its render plugin
//! registers it.

mod common;

use bevy::asset::{AssetPlugin, LoadState};
use bevy::image::{CompressedImageFormats, ImageLoader, ImageLoaderSettings, ImagePlugin};
use bevy::prelude::*;
use bevy::render::render_resource::{TextureDimension, TextureFormat};
use displace_bevy::{DistanceMapping, Encoding};
use displace_core::distance_map::Format;
use displace_core::{Address, BakeOptions, DisplacementMap, HeightMap};
use std::path::Path;
use std::time::Duration;

/// A fresh directory under the system's temporary one (no tempfile crate:
/// its rustix features would rebuild Bevy's asset stack for the tests).
fn temp_dir(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("displace-bevy-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn small_map(address: Address) -> DisplacementMap {
    common::baked("gen:studded", [32, 32], address, [32, 32, 8], 0.1)
}

fn ktx2(map: &DisplacementMap, format: Format) -> Vec<u8> {
    displace_core::io::ktx2::to_bytes(&map.distance, map.extent, format).unwrap()
}

/// An app with Bevy's asset server and its image loader over `dir`.
fn loader_app(dir: &Path) -> App {
    let mut app = App::new();
    app.add_plugins((
        MinimalPlugins,
        AssetPlugin {
            file_path: dir.to_string_lossy().into_owned(),
            ..default()
        },
        ImagePlugin::default(),
    ));
    app.register_asset_loader(ImageLoader::new(CompressedImageFormats::NONE));
    app.finish();
    app
}

/// Loads `name` with linear (non-sRGB) settings and pumps the app until the
/// load settles.
fn load(app: &mut App, name: &str) -> (Handle<Image>, LoadState) {
    let handle: Handle<Image> = app
        .world()
        .resource::<AssetServer>()
        .load_builder()
        .with_settings(|s: &mut ImageLoaderSettings| s.is_srgb = false)
        .load(name.to_string());
    for _ in 0..2000 {
        app.update();
        let state = app.world().resource::<AssetServer>().load_state(&handle);
        if matches!(state, LoadState::Loaded | LoadState::Failed(_)) {
            return (handle, state);
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    panic!("{name}: the load never settled");
}

#[test]
fn our_ktx2_loads_through_bevys_image_loader_as_a_3d_texture() {
    let dir = temp_dir("load");
    let map = small_map(Address::Clamp);
    for (format, encoding, wgpu_format) in [
        (Format::R8, Encoding::R8, TextureFormat::R8Unorm),
        (Format::R16F, Encoding::R16F, TextureFormat::R16Float),
    ] {
        let name = format!("map_{}.ktx2", format.name());
        std::fs::write(dir.join(&name), ktx2(&map, format)).unwrap();
        let mut app = loader_app(&dir);
        let (handle, state) = load(&mut app, &name);
        assert!(matches!(state, LoadState::Loaded), "{name}: {state:?}");
        let images = app.world().resource::<Assets<Image>>();
        let image = images.get(&handle).unwrap();
        let desc = &image.texture_descriptor;
        assert_eq!(desc.dimension, TextureDimension::D3, "{name}");
        assert_eq!(desc.format, wgpu_format, "{name}");
        assert_eq!(
            [
                desc.size.width,
                desc.size.height,
                desc.size.depth_or_array_layers
            ],
            [32, 32, 8],
            "{name}"
        );
        // Bevy's texels are exactly the ones the material uploads from the
        // bake itself.
        let mut own = Assets::<Image>::default();
        let mapping = DistanceMapping::from_map(&map, encoding, &mut own).unwrap();
        let uploaded = own.get(&mapping.distance).unwrap();
        assert_eq!(image.data, uploaded.data, "{name}: texels");
    }
}

#[test]
fn from_ktx2_gives_the_trace_constants_of_the_bake() {
    for address in [Address::Clamp, Address::Repeat] {
        let map = small_map(address);
        for (format, encoding) in [(Format::R8, Encoding::R8), (Format::R16F, Encoding::R16F)] {
            let mut images = Assets::<Image>::default();
            let baked = DistanceMapping::from_map(&map, encoding, &mut images).unwrap();
            let loaded =
                DistanceMapping::from_ktx2(&ktx2(&map, format), &map.height, &mut images).unwrap();
            // The file's values are already rounded, and its underestimate
            // bound says so; rounding them again changes no value but
            // counts the R8 quantum once more: the KTX2 route's exact walk
            // is at most 1.5 quanta wider, never narrower.
            let quantum = 4.0 / 255.0;
            assert!(
                loaded.map.band >= baked.map.band
                    && loaded.map.band - baked.map.band <= 1.5 * quantum + 1e-6,
                "{address:?} {format:?}: band {} against {}",
                loaded.map.band,
                baked.map.band
            );
            let same_band = displace_bevy::MapParams {
                band: baked.map.band,
                ..loaded.map
            };
            assert_eq!(same_band, baked.map, "{address:?} {format:?}");
            assert_eq!(loaded.settings, baked.settings, "{address:?} {format:?}");
            let a = images.get(&loaded.distance).unwrap();
            let b = images.get(&baked.distance).unwrap();
            assert_eq!(a.data, b.data);
            assert_eq!(a.texture_descriptor.dimension, TextureDimension::D3);
        }
    }
}

/// Cut short, bad magic, and the level index pointing past the end: Bevy's
/// loader refuses these.
fn malformed(good: &[u8]) -> Vec<(&'static str, Vec<u8>)> {
    let mut past_end = good.to_vec();
    past_end[80..88].copy_from_slice(&(good.len() as u64 * 4).to_le_bytes()); // level 0 offset
    let mut magic = good.to_vec();
    magic[1] = b'X';
    vec![
        ("truncated", good[..good.len() / 2].to_vec()),
        ("header only", good[..60].to_vec()),
        ("bad magic", magic),
        ("level past the end", past_end),
    ]
}

#[test]
fn malformed_ktx2_is_bevys_load_error_not_a_panic() {
    let dir = temp_dir("malformed");
    let map = small_map(Address::Clamp);
    let good = ktx2(&map, Format::R8);
    for (what, bytes) in malformed(&good) {
        let name = format!("{}.ktx2", what.replace(' ', "_"));
        std::fs::write(dir.join(&name), &bytes).unwrap();
        let mut app = loader_app(&dir);
        let (_, state) = load(&mut app, &name);
        assert!(matches!(state, LoadState::Failed(_)), "{what}: {state:?}");
        let mut images = Assets::<Image>::default();
        assert!(
            DistanceMapping::from_ktx2(&bytes, &map.height, &mut images).is_err(),
            "{what}: from_ktx2 accepted it"
        );
        assert!(
            displace_bevy::load_ktx2(&bytes, Address::Clamp).is_err(),
            "{what}: Bevy's decoder accepted it"
        );
    }
}

/// A header whose width disagrees with its level's length: Bevy 0.19.1's
/// KTX2 decoder accepts it (an image whose data does not fill it); ours
/// refuses it, so `from_ktx2` never hands Bevy such an image.
#[test]
fn a_header_larger_than_its_level_is_refused_by_from_ktx2() {
    let map = small_map(Address::Clamp);
    let mut bytes = ktx2(&map, Format::R8);
    bytes[20..24].copy_from_slice(&u32::MAX.to_le_bytes()); // pixelWidth
    let mut images = Assets::<Image>::default();
    assert!(DistanceMapping::from_ktx2(&bytes, &map.height, &mut images).is_err());
    assert!(images.is_empty(), "nothing was uploaded");
}

#[test]
fn r32f_and_mismatched_addressing_are_refused() {
    let map = small_map(Address::Clamp);
    let mut images = Assets::<Image>::default();
    let err = DistanceMapping::from_ktx2(&ktx2(&map, Format::R32F), &map.height, &mut images)
        .unwrap_err();
    assert!(err.to_string().contains("r32f"), "{err}");
    let repeat = HeightMap::new(32, 32, map.height.data().to_vec(), Address::Repeat).unwrap();
    let err =
        DistanceMapping::from_ktx2(&ktx2(&map, Format::R8), &repeat, &mut images).unwrap_err();
    assert!(err.to_string().contains("addressing"), "{err}");
}

#[test]
fn bake_helper_uploads_height_and_distance() {
    let mut images = Assets::<Image>::default();
    let m = DistanceMapping::bake_source(
        "gen:gaussian",
        Address::Clamp,
        &BakeOptions {
            size: [32, 32, 8],
            ..Default::default()
        },
        Encoding::R8,
        &mut images,
    )
    .unwrap();
    let h = images.get(&m.height).unwrap();
    assert_eq!(h.texture_descriptor.format, TextureFormat::R32Float);
    assert_eq!(h.texture_descriptor.dimension, TextureDimension::D2);
    assert_eq!(m.map.height_size, UVec2::new(256, 256));
    assert_eq!(m.map.dist_size, UVec3::new(32, 32, 8));
    assert!(m.map.tau > 0.0 && m.map.band > m.map.tau);
    assert_eq!(m.settings.depth, 0.1);
    assert!(DistanceMapping::bake_source(
        "/nonexistent/height.png",
        Address::Clamp,
        &BakeOptions::default(),
        Encoding::R8,
        &mut images
    )
    .is_err());
}
