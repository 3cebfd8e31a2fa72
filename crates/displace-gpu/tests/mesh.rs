//! The mesh path: MikkTSpace frames on the built-in meshes, and a flat
//! mesh drawn through the mesh path against the same face drawn as a shell
//! box.

mod common;

use common::{random_map, Rng};
use displace_core::Address;
use displace_gpu::mesh::tangent_frames;
use displace_gpu::test_support::test_context;
use displace_gpu::{DistanceTexture, MeshTriangle, PlaneScene, Renderer, ShellMesh};
use displace_scene::builtin_mesh;
use glam::{Vec2, Vec3};

fn builtin(name: &str) -> Vec<MeshTriangle> {
    builtin_mesh::generate(name)
        .unwrap()
        .triangles
        .iter()
        .map(|t| MeshTriangle {
            positions: t.positions,
            normals: t.normals.unwrap(),
            uvs: t.uvs,
        })
        .collect()
}

/// Every corner of every built-in mesh: the tangent is unit length and
/// orthogonal to the vertex normal, and the tangent and bitangent point
/// the way of the triangle's texture gradients `dP/du` and `dP/dv` (so the
/// frame is the texture's, not a mirrored or rotated one), with magnitudes
/// of the same order as the triangle's.
#[test]
fn mikktspace_frames_follow_the_texture_on_every_builtin() {
    for name in builtin_mesh::NAMES {
        let tris = builtin(name);
        let frames = tangent_frames(&tris).unwrap();
        let mut corners = 0;
        for (k, (t, f)) in tris.iter().zip(&frames).enumerate() {
            let [p0, p1, p2] = t.positions;
            let (d1, d2) = (t.uvs[1] - t.uvs[0], t.uvs[2] - t.uvs[0]);
            let det = d1.x * d2.y - d2.x * d1.y;
            let dpdu = (d2.y * (p1 - p0) - d1.y * (p2 - p0)) / det;
            let dpdv = (-d2.x * (p1 - p0) + d1.x * (p2 - p0)) / det;
            for (c, (&n, &fr)) in t.normals.iter().zip(f).enumerate() {
                let tangent = fr.tangent;
                let bitangent = fr.sign * n.cross(tangent);
                assert!((tangent.length() - 1.0).abs() < 1e-4, "{name} {k}");
                assert!(
                    tangent.dot(n).abs() < 1e-4,
                    "{name} {k}: t.n = {}",
                    tangent.dot(n)
                );
                assert!(
                    tangent.dot(dpdu.normalize()) > 0.5,
                    "{name} triangle {k} corner {c}: tangent {tangent} vs dP/du {dpdu}"
                );
                assert!(
                    bitangent.dot(dpdv.normalize()) > 0.5,
                    "{name} triangle {k} corner {c}: bitangent {bitangent} vs dP/dv {dpdv}"
                );
                assert_eq!(fr.sign, 1.0, "{name} {k}: the built-ins are not mirrored");
                let ratio = fr.scale / Vec2::new(dpdu.length(), dpdv.length());
                assert!(
                    ratio.min_element() > 0.2 && ratio.max_element() < 5.0,
                    "{name} {k}: magnitudes {} vs the triangle's {}",
                    fr.scale,
                    Vec2::new(dpdu.length(), dpdv.length())
                );
                corners += 1;
            }
        }
        assert_eq!(corners, 3 * tris.len());
    }
}

/// A mesh of the face's two triangles, drawn by the mesh path, shows what
/// the shell box of the same face shows: the UV AOV (u, v and hit kind)
/// agrees on >= 99.5% of a 64x64 frame seen obliquely (walls included).
#[test]
fn a_flat_mesh_draws_like_the_shell_box() {
    let Some(ctx) = test_context() else { return };
    for (seed, address) in [(5, Address::Clamp), (6, Address::Repeat)] {
        let mut rng = Rng::new(seed);
        let map = random_map(&mut rng, address);
        let scene = PlaneScene::for_map(&map, [64, 64]);
        let boxed = Renderer::new(ctx, &map, DistanceTexture::R32Load)
            .unwrap()
            .render(ctx, &scene)
            .unwrap();
        let face = *scene.draw.face().expect("the built-in face");
        let corner = |u: f32, v: f32| face.origin + u * face.tangent + v * face.bitangent;
        let uv = [Vec2::ZERO, Vec2::X, Vec2::ONE, Vec2::Y];
        let tris: Vec<MeshTriangle> = [[0, 1, 2], [0, 2, 3]]
            .into_iter()
            .map(|i| MeshTriangle {
                positions: i.map(|k| corner(uv[k].x, uv[k].y)),
                normals: [Vec3::Z; 3],
                uvs: i.map(|k| uv[k]),
            })
            .collect();
        let shell = ShellMesh::new(&tris, address).unwrap();
        assert_eq!(shell.tiles, [1.0, 1.0]);
        let meshed = Renderer::checker_mesh(ctx, &map, DistanceTexture::R32Load, &shell)
            .unwrap()
            .render(ctx, &scene)
            .unwrap();
        let (mut agree, mut covered) = (0, 0);
        for (a, b) in boxed.uv.iter().zip(&meshed.uv) {
            covered += (a[2] != 0.0) as u32;
            let same = a[2] == b[2]
                && (a[2] == 0.0 || ((a[0] - b[0]).abs() < 1e-3 && (a[1] - b[1]).abs() < 1e-3));
            agree += same as u32;
        }
        eprintln!("{address:?}: mesh path agrees with the box on {agree} of 4096 pixels ({covered} covered)");
        assert!(covered > 1000, "{covered}");
        assert!(
            agree as f64 >= 0.995 * 4096.0,
            "{address:?}: {agree} of 4096"
        );
    }
}

/// Walls go where the lifted tops part: each of a cube's 12 edges is a
/// crease (one wall per side), its face diagonals are not; a smooth closed
/// mesh has none, and with a repeating map its window gets a tile of margin
/// all round so rays cross its texture seams.
#[test]
fn walls_stand_on_creases_and_boundaries_only() {
    let cube = ShellMesh::new(&builtin("cube"), Address::Clamp).unwrap();
    assert_eq!(cube.walls, 24);
    let torus = ShellMesh::new(&builtin("torus"), Address::Repeat).unwrap();
    assert_eq!(torus.walls, 0);
    assert_eq!(torus.tiles, [3.0, 3.0]);
    assert_eq!(torus.uv_shift, Vec2::splat(-1.0));
    let plane = ShellMesh::new(&builtin("plane"), Address::Repeat).unwrap();
    assert_eq!(plane.walls, 4);
    assert_eq!(plane.tiles, [1.0, 1.0]);
}
