//! `cargo run -p displace-bevy --features window --example stone`: a
//! displaced stone floor, sphere and torus under a moving light (GPU Gems 2
//! ch. 8, figure 8-1's surface; the sphere and torus through curved
//! shells), orbit camera (left drag or arrow keys, wheel to
//! zoom). `M` switches the same height map between our distance mapping
//! (early out and exact refinement, then Donnelly's fixed loop) and Bevy's
//! own parallax occlusion and relief mapping (`ParallaxMappingMethod`);
//! the window title names the method and the frame time.

mod common;

use bevy::input::mouse::{AccumulatedMouseMotion, AccumulatedMouseScroll};
use bevy::pbr::ParallaxMappingMethod;
use bevy::prelude::*;
use displace_bevy::{DistanceMappedMaterial, MarchMethod};

/// The methods `M` cycles through.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Shown {
    DistanceEarlyOut,
    DistanceFixed,
    BevyOcclusion,
    BevyRelief,
}

impl Shown {
    fn next(self) -> Self {
        match self {
            Shown::DistanceEarlyOut => Shown::DistanceFixed,
            Shown::DistanceFixed => Shown::BevyOcclusion,
            Shown::BevyOcclusion => Shown::BevyRelief,
            Shown::BevyRelief => Shown::DistanceEarlyOut,
        }
    }
    fn label(self) -> &'static str {
        match self {
            Shown::DistanceEarlyOut => "distance mapping (early out + exact refinement)",
            Shown::DistanceFixed => "distance mapping (Donnelly's fixed loop, 16 steps)",
            Shown::BevyOcclusion => "Bevy parallax occlusion mapping (16 layers)",
            Shown::BevyRelief => "Bevy relief mapping (16 layers, 5 steps)",
        }
    }
}

#[derive(Resource)]
struct Demo {
    shown: Shown,
    stone: common::Stone,
    /// Bevy's parallax materials for floor and sphere, at the same depths.
    bevy: [Handle<StandardMaterial>; 2],
}

#[derive(Component)]
struct Orbit {
    yaw: f32,
    pitch: f32,
    distance: f32,
}

#[derive(Component)]
struct MovingLight;

fn main() {
    App::new()
        .add_plugins((DefaultPlugins, displace_bevy::DistanceMappingPlugin))
        .add_systems(Startup, setup)
        .add_systems(Update, (switch_method, orbit, move_light, title))
        .run();
}

fn setup(world: &mut World) {
    let stone = common::spawn(world);
    let bevy = common::bevy_parallax(world, &stone, ParallaxMappingMethod::Occlusion);
    world.spawn((
        Camera3d::default(),
        common::camera_transform(),
        Orbit {
            yaw: 0.0,
            pitch: 0.6,
            distance: 3.9,
        },
    ));
    let light = world
        .query_filtered::<Entity, With<PointLight>>()
        .iter(world)
        .next();
    if let Some(light) = light {
        world.entity_mut(light).insert(MovingLight);
    }
    world.insert_resource(Demo {
        shown: Shown::DistanceEarlyOut,
        stone,
        bevy,
    });
}

fn switch_method(world: &mut World) {
    if !world
        .resource::<ButtonInput<KeyCode>>()
        .just_pressed(KeyCode::KeyM)
    {
        return;
    }
    world.resource_scope(|world, mut demo: Mut<Demo>| {
        demo.shown = demo.shown.next();
        match demo.shown {
            Shown::DistanceEarlyOut | Shown::DistanceFixed => {
                let method = if demo.shown == Shown::DistanceFixed {
                    MarchMethod::Fixed
                } else {
                    MarchMethod::EarlyOut
                };
                // The floor's march; the curved sphere's chords keep theirs.
                {
                    let mut ours = world.resource_mut::<Assets<DistanceMappedMaterial>>();
                    if let Some(mut m) = ours.get_mut(&demo.stone.floor_material) {
                        m.extension = m.extension.clone().with_method(method).with_iterations(16);
                    };
                }
                common::show_ours(world, &demo.stone);
            }
            Shown::BevyOcclusion | Shown::BevyRelief => {
                let method = if demo.shown == Shown::BevyRelief {
                    ParallaxMappingMethod::Relief { max_steps: 5 }
                } else {
                    ParallaxMappingMethod::Occlusion
                };
                let mut theirs = world.resource_mut::<Assets<StandardMaterial>>();
                for handle in &demo.bevy {
                    if let Some(mut m) = theirs.get_mut(handle) {
                        m.parallax_mapping_method = method;
                    }
                }
                common::show_bevy(world, &demo.stone, &demo.bevy);
            }
        }
    });
}

fn orbit(
    buttons: Res<ButtonInput<MouseButton>>,
    keys: Res<ButtonInput<KeyCode>>,
    motion: Res<AccumulatedMouseMotion>,
    scroll: Res<AccumulatedMouseScroll>,
    time: Res<Time>,
    mut cameras: Query<(&mut Orbit, &mut Transform)>,
) {
    let dt = time.delta_secs();
    for (mut o, mut t) in &mut cameras {
        if buttons.pressed(MouseButton::Left) {
            o.yaw -= motion.delta.x * 0.005;
            o.pitch += motion.delta.y * 0.005;
        }
        let key = |k: KeyCode| if keys.pressed(k) { dt } else { 0.0 };
        o.yaw += key(KeyCode::ArrowLeft) - key(KeyCode::ArrowRight);
        o.pitch += key(KeyCode::ArrowUp) - key(KeyCode::ArrowDown);
        o.pitch = o.pitch.clamp(0.05, 1.5);
        o.distance = (o.distance * (1.0 - 0.1 * scroll.delta.y)).clamp(0.5, 20.0);
        let target = Vec3::new(0.0, 0.0, 0.3);
        let offset = Vec3::new(
            o.distance * o.pitch.cos() * o.yaw.sin(),
            o.distance * o.pitch.sin(),
            -o.distance * o.pitch.cos() * o.yaw.cos(),
        );
        *t = Transform::from_translation(target + offset).looking_at(target, Vec3::Y);
    }
}

fn move_light(time: Res<Time>, mut lights: Query<&mut Transform, With<MovingLight>>) {
    let a = time.elapsed_secs() * 0.4;
    for mut t in &mut lights {
        t.translation = Vec3::new(3.0 * a.cos(), 3.0, 3.0 * a.sin());
    }
}

fn title(demo: Res<Demo>, time: Res<Time>, mut windows: Query<&mut Window>) {
    for mut w in &mut windows {
        w.title = format!(
            "displace-bevy stone: {} (M to switch), {:.1} ms",
            demo.shown.label(),
            time.delta_secs() * 1000.0
        );
    }
}
