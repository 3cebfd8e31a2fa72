//! One Bevy app without a window, driven frame by frame, rendering a camera
//! into an image and reading it back: the `headless` example's PNG and the
//! tests' comparisons against `displace-gpu` (which renders headless too),
//! on any adapter wgpu finds, Mesa's lavapipe included.

use crate::DistanceMappingPlugin;
use bevy::app::SubApps;
use bevy::asset::RenderAssetUsages;
use bevy::camera::RenderTarget;
use bevy::prelude::*;
use bevy::render::render_resource::{
    Extent3d, PollType, TextureDimension, TextureFormat, TextureUsages,
};
use bevy::render::renderer::RenderDevice;
use bevy::render::view::screenshot::{Screenshot, ScreenshotCaptured};
use bevy::render::RenderPlugin;
use bevy::window::{ExitCondition, WindowPlugin};
use std::sync::{Arc, Mutex};

/// Frames pumped after a screenshot is requested before giving up: the
/// read-back lands a frame or two later.
const CAPTURE_FRAMES: u32 = 16;
/// Frames rendered before the screenshot: assets (meshes, images, material
/// bind groups) are prepared over the first frames after they are added.
const WARMUP_FRAMES: u32 = 4;

/// Why a headless frame did not come back.
#[derive(Debug, thiserror::Error)]
pub enum HeadlessError {
    /// The render world never delivered the requested screenshot (no
    /// adapter, or a pipeline that failed to build: Bevy logs why).
    #[error("no frame came back after {0} updates (is there a GPU adapter? see Bevy's log)")]
    NoFrame(u32),
}

/// A windowless app with [`DistanceMappingPlugin`] and one render-target
/// image; the caller spawns the scene into [`Headless::world_mut`] with a
/// camera on [`Headless::target`].
pub struct Headless {
    apps: SubApps,
    target: Handle<Image>,
}

impl Headless {
    /// An app whose pipelines compile synchronously (the first frame is
    /// complete) and a `width` x `height` target of `format`
    /// (`Rgba8UnormSrgb` for pictures, `Rgba16Float` for data).
    pub fn new(width: u32, height: u32, format: TextureFormat) -> Self {
        Self::with(width, height, format, |_| {})
    }

    /// [`Headless::new`], with `configure` adding plugins and render-world
    /// systems before the app is finished.
    pub fn with(
        width: u32,
        height: u32,
        format: TextureFormat,
        configure: impl FnOnce(&mut App),
    ) -> Self {
        let mut app = App::new();
        let plugins = DefaultPlugins
            .set(WindowPlugin {
                primary_window: None,
                exit_condition: ExitCondition::DontExit,
                ..default()
            })
            .set(RenderPlugin {
                synchronous_pipeline_compilation: true,
                ..default()
            });
        #[cfg(feature = "window")]
        let plugins = plugins.disable::<bevy::winit::WinitPlugin>();
        app.add_plugins((plugins, DistanceMappingPlugin));
        configure(&mut app);
        app.finish();
        app.cleanup();
        let mut target = Image::new_uninit(
            Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
            TextureDimension::D2,
            format,
            RenderAssetUsages::RENDER_WORLD,
        );
        target.texture_descriptor.usage |= TextureUsages::RENDER_ATTACHMENT
            | TextureUsages::COPY_SRC
            | TextureUsages::TEXTURE_BINDING;
        let target = app.world_mut().resource_mut::<Assets<Image>>().add(target);
        Self {
            apps: std::mem::take(app.sub_apps_mut()),
            target,
        }
    }

    /// The main world, to spawn the scene into.
    pub fn world_mut(&mut self) -> &mut World {
        self.apps.main.world_mut()
    }

    /// The render target a camera of the scene must carry.
    pub fn target(&self) -> RenderTarget {
        RenderTarget::Image(self.target.clone().into())
    }

    /// One frame: update, extract, render, and wait for the GPU.
    pub fn update(&mut self) {
        self.apps.update();
        if let Some(device) = self.apps.main.world().get_resource::<RenderDevice>() {
            // A lost device shows as a missing frame in `capture`.
            let _ = device.wgpu_device().poll(PollType::Wait {
                submission_index: None,
                timeout: None,
            });
        }
    }

    /// Renders frames until a screenshot of the target comes back, and
    /// returns it (in the target's format).
    pub fn capture(&mut self) -> Result<Image, HeadlessError> {
        for _ in 0..WARMUP_FRAMES {
            self.update();
        }
        let slot: Arc<Mutex<Option<Image>>> = Arc::default();
        let sink = slot.clone();
        let target = self.target.clone();
        self.world_mut().spawn(Screenshot::image(target)).observe(
            move |captured: On<ScreenshotCaptured>| {
                if let Ok(mut s) = sink.lock() {
                    *s = Some(captured.image.clone());
                }
            },
        );
        for _ in 0..CAPTURE_FRAMES {
            self.update();
            if let Some(image) = slot.lock().ok().and_then(|mut s| s.take()) {
                return Ok(image);
            }
        }
        Err(HeadlessError::NoFrame(CAPTURE_FRAMES))
    }
}
