//! The viewer's window: a winit 0.30 event loop, a wgpu surface, and each
//! frame drawn by [`encode_faces`] into the frame targets and presented by
//! [`Presenter`] on the GPU (no read-back, except for `--screenshot`). The
//! raster pipeline writes colour and the UV AOV to fixed formats, so the
//! frame is rendered offscreen and the present pass copies it texel for
//! texel to whatever format the surface has.
//!
//! Resizes reconfigure the surface and targets; a zero-sized (minimised)
//! window draws nothing; an outdated surface is reconfigured and a lost one
//! recreated; closing or Escape ends the loop and returns.

use super::controls::{key_action, key_name, Action, ZOOM_STEP};
use super::overlay::{Output, Presenter};
use super::{ViewScene, ViewState};
use crate::descriptors::texture_2d_descriptor;
use crate::raster::{copy_to_readback, encode_faces, Targets, COLOR_FORMAT};
use crate::{Draw, Error, GpuContext, Renderer};
use std::sync::Arc;
use std::time::{Duration, Instant};
use winit::application::ApplicationHandler;
use winit::dpi::{PhysicalPosition, PhysicalSize};
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::window::{Window, WindowId};

/// Degrees of orbit per pixel of mouse drag.
const DRAG_DEGREES_PER_PIXEL: f32 = 0.3;
/// Wheel pixels (touchpads) per notch.
const PIXELS_PER_NOTCH: f64 = 40.0;
/// How often the frame time on screen changes: re-rasterising the text
/// every frame would flicker and cost a texture upload per frame.
const TEXT_REFRESH: Duration = Duration::from_millis(500);

/// How to run the window.
#[derive(Clone, Debug)]
pub struct ViewOptions {
    /// Requested inner size in pixels.
    pub size: [u32; 2],
    /// Stop after this many presented frames.
    pub frames: Option<u32>,
    /// Read the last of `frames` back as it was presented.
    pub screenshot: bool,
    /// Applied in order before the first frame.
    pub script: Vec<Action>,
    /// Window title prefix.
    pub title: String,
}

/// A presented frame read back: sRGB RGBA8, rows top to bottom.
pub struct Screenshot {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Four bytes a pixel.
    pub rgba8: Vec<u8>,
}

/// Opens the window, builds the scene with `make` on its device, and runs
/// until the window closes or `frames` frames were presented. Returns the
/// screenshot when one was asked for.
pub fn run<E, F>(opts: ViewOptions, make: F) -> Result<Option<Screenshot>, E>
where
    E: From<Error>,
    F: FnOnce(&GpuContext) -> Result<ViewScene, E>,
{
    let event_loop = EventLoop::new().map_err(|e| Error::Window(e.to_string()))?;
    event_loop.set_control_flow(ControlFlow::Poll);
    let mut app = App {
        opts,
        make: Some(make),
        running: None,
        error: None,
        screenshot: None,
    };
    event_loop
        .run_app(&mut app)
        .map_err(|e| Error::Window(e.to_string()))?;
    if let Some(e) = app.error {
        return Err(e);
    }
    if app.opts.screenshot && app.screenshot.is_none() {
        return Err(Error::Window("the window closed before the screenshot frame".into()).into());
    }
    Ok(app.screenshot)
}

struct App<E, F> {
    opts: ViewOptions,
    make: Option<F>,
    running: Option<Running>,
    error: Option<E>,
    screenshot: Option<Screenshot>,
}

struct Running {
    window: Arc<Window>,
    instance: wgpu::Instance,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    ctx: GpuContext,
    scene: ViewScene,
    base: Vec<Draw>,
    state: ViewState,
    presenter: Presenter,
    targets: Option<Targets>,
    frames: u32,
    last_frame: Option<Instant>,
    frame_ms: Option<f64>,
    shown_ms: Option<f64>,
    shown_at: Option<Instant>,
    title: String,
    dragging: bool,
    cursor: Option<PhysicalPosition<f64>>,
    /// Script commands still to apply, the next one last.
    script: Vec<Action>,
    /// A script command asked to quit.
    quit: bool,
}

impl<E: From<Error>, F: FnOnce(&GpuContext) -> Result<ViewScene, E>> ApplicationHandler
    for App<E, F>
{
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.running.is_some() {
            return;
        }
        let Some(make) = self.make.take() else {
            return;
        };
        match self.start(event_loop, make) {
            Ok(r) => {
                r.window.request_redraw();
                self.running = Some(r);
            }
            Err(e) => {
                self.error = Some(e);
                event_loop.exit();
            }
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _: WindowId, event: WindowEvent) {
        let Some(r) = self.running.as_mut() else {
            return;
        };
        let action = match event {
            WindowEvent::CloseRequested => Some(Action::Quit),
            WindowEvent::RedrawRequested => {
                match r.frame(self.opts.frames, self.opts.screenshot) {
                    Ok(Some(shot)) => {
                        self.screenshot = Some(shot);
                        event_loop.exit();
                    }
                    Ok(None) if r.quit || self.opts.frames.is_some_and(|n| r.frames >= n) => {
                        event_loop.exit()
                    }
                    Ok(None) => {}
                    Err(e) => {
                        self.error = Some(e.into());
                        event_loop.exit();
                    }
                }
                None
            }
            WindowEvent::KeyboardInput { event, .. } if event.state == ElementState::Pressed => {
                key_name(&event.logical_key).and_then(|k| key_action(&k))
            }
            WindowEvent::MouseInput {
                state,
                button: MouseButton::Left,
                ..
            } => {
                r.dragging = state == ElementState::Pressed;
                None
            }
            WindowEvent::CursorMoved { position, .. } => {
                let turn = r.cursor.filter(|_| r.dragging).map(|p| Action::Orbit {
                    yaw: -(position.x - p.x) as f32 * DRAG_DEGREES_PER_PIXEL,
                    raise: (position.y - p.y) as f32 * DRAG_DEGREES_PER_PIXEL,
                });
                r.cursor = Some(position);
                turn
            }
            WindowEvent::MouseWheel { delta, .. } => {
                let notches = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y as f64,
                    MouseScrollDelta::PixelDelta(p) => p.y / PIXELS_PER_NOTCH,
                };
                Some(Action::Zoom(ZOOM_STEP.powf(-notches as f32)))
            }
            _ => None,
        };
        if let Some(a) = action {
            if r.state.apply(a) {
                event_loop.exit();
            }
        }
    }

    fn about_to_wait(&mut self, _: &ActiveEventLoop) {
        if let Some(r) = &self.running {
            r.window.request_redraw();
        }
    }
}

impl<E: From<Error>, F: FnOnce(&GpuContext) -> Result<ViewScene, E>> App<E, F> {
    fn start(&mut self, event_loop: &ActiveEventLoop, make: F) -> Result<Running, E> {
        let [w, h] = self.opts.size;
        let window = Arc::new(
            event_loop
                .create_window(
                    Window::default_attributes()
                        .with_title(&self.opts.title)
                        .with_inner_size(PhysicalSize::new(w, h)),
                )
                .map_err(|e| Error::Window(e.to_string()))?,
        );
        let instance = wgpu::Instance::new(
            wgpu::InstanceDescriptor::new_with_display_handle_from_env(Box::new(window.clone())),
        );
        let surface = create_surface(&instance, &window)?;
        let ctx = GpuContext::for_surface(&instance, &surface)?;
        let caps = surface.get_capabilities(&ctx.adapter);
        let Some(&format) = caps
            .formats
            .iter()
            .find(|f| f.is_srgb())
            .or(caps.formats.first())
        else {
            return Err(
                Error::Window(format!("{} cannot present to this window", ctx.info.name)).into(),
            );
        };
        let config = wgpu::SurfaceConfiguration {
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            format,
            width: w,
            height: h,
            // Unthrottled where the platform allows, so the frame time on
            // screen is the render's, not the display's refresh.
            present_mode: wgpu::PresentMode::AutoNoVsync,
            desired_maximum_frame_latency: 2,
            alpha_mode: caps.alpha_modes[0],
            view_formats: vec![],
        };
        ctx.checked("configuring the window surface", || {
            surface.configure(&ctx.device, &config)
        })?;
        let scene = make(&ctx)?;
        let base: Vec<Draw> = scene.draws.iter().map(|(_, d)| *d).collect();
        let state = ViewState::new(&scene.view, &base)?;
        let presenter = Presenter::new(&ctx)?;
        Ok(Running {
            title: self.opts.title.clone(),
            window,
            instance,
            surface,
            config,
            ctx,
            scene,
            base,
            state,
            presenter,
            targets: None,
            frames: 0,
            last_frame: None,
            frame_ms: None,
            shown_ms: None,
            shown_at: None,
            dragging: false,
            cursor: None,
            script: self.opts.script.iter().rev().copied().collect(),
            quit: false,
        })
    }
}

fn create_surface(
    instance: &wgpu::Instance,
    window: &Arc<Window>,
) -> Result<wgpu::Surface<'static>, Error> {
    instance
        .create_surface(window.clone())
        .map_err(|e| Error::Window(format!("creating the surface: {e}")))
}

impl Running {
    fn configure(&mut self, [w, h]: [u32; 2]) -> Result<(), Error> {
        self.config.width = w;
        self.config.height = h;
        self.ctx.checked("configuring the window surface", || {
            self.surface.configure(&self.ctx.device, &self.config)
        })
    }

    /// Draws and presents one frame; returns the screenshot when this was
    /// the last of `frames` and one was asked for.
    fn frame(
        &mut self,
        frames: Option<u32>,
        screenshot: bool,
    ) -> Result<Option<Screenshot>, Error> {
        self.run_script();
        if self.quit {
            return Ok(None);
        }
        let PhysicalSize {
            width: w,
            height: h,
        } = self.window.inner_size();
        if w == 0 || h == 0 {
            return Ok(None); // minimised: nothing to draw into
        }
        if [self.config.width, self.config.height] != [w, h] {
            self.configure([w, h])?;
        }
        let surface_texture = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t) => t,
            wgpu::CurrentSurfaceTexture::Suboptimal(t) => {
                // Presented as is; the next frame reconfigures.
                self.config.width = 0;
                t
            }
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => {
                return Ok(None)
            }
            wgpu::CurrentSurfaceTexture::Outdated => {
                self.configure([w, h])?;
                return Ok(None);
            }
            wgpu::CurrentSurfaceTexture::Lost => {
                self.surface = create_surface(&self.instance, &self.window)?;
                self.configure([w, h])?;
                return Ok(None);
            }
            wgpu::CurrentSurfaceTexture::Validation => {
                return Err(Error::Gpu {
                    during: "acquiring the window's next frame".into(),
                    message: "validation error".into(),
                })
            }
        };
        self.update_text()?;
        if self.targets.as_ref().is_none_or(|t| t.size() != [w, h]) {
            self.targets = Some(Targets::new(&self.ctx, [w, h]));
        }
        let targets = self.targets.as_ref().expect("made above");
        let (view, planes) = self.state.frame(&self.scene.view, &self.base, [w, h]);
        let draws: Vec<(&Renderer, &Draw)> = self
            .scene
            .draws
            .iter()
            .map(|(r, _)| r)
            .zip(&planes)
            .collect();
        let mut encoder = self.ctx.device.create_command_encoder(&Default::default());
        encode_faces(
            &self.ctx,
            &mut encoder,
            targets,
            &view,
            &draws,
            self.scene.background,
        )?;
        let view = surface_texture.texture.create_view(&Default::default());
        let hud = self.state.settings.hud;
        let frame_view = targets.color_view();
        self.presenter.encode(
            &self.ctx,
            &mut encoder,
            frame_view,
            &Output {
                view: &view,
                format: self.config.format,
                size: [w, h],
            },
            hud,
        )?;
        let last = frames.is_some_and(|n| self.frames + 1 >= n);
        let readback = if last && screenshot {
            let shot = self.ctx.device.create_texture(&texture_2d_descriptor(
                "screenshot",
                [w, h],
                1,
                COLOR_FORMAT,
                wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            ));
            self.presenter.encode(
                &self.ctx,
                &mut encoder,
                frame_view,
                &Output {
                    view: &shot.create_view(&Default::default()),
                    format: COLOR_FORMAT,
                    size: [w, h],
                },
                hud,
            )?;
            Some(copy_to_readback(&self.ctx, &mut encoder, &shot, 4, [w, h]))
        } else {
            None
        };
        let commands = self
            .ctx
            .checked("finishing the frame", || encoder.finish())?;
        self.ctx.queue.submit([commands]);
        self.window.pre_present_notify();
        surface_texture.present();
        self.frames += 1;
        let now = Instant::now();
        if let Some(prev) = self.last_frame {
            let ms = (now - prev).as_secs_f64() * 1e3;
            self.frame_ms = Some(self.frame_ms.map_or(ms, |m| 0.8 * m + 0.2 * ms));
        }
        self.last_frame = Some(now);
        let Some((buffer, row)) = readback else {
            return Ok(None);
        };
        let bytes = self.ctx.read_buffer(&buffer)?;
        let rgba8 = bytes
            .chunks_exact(row as usize)
            .flat_map(|r| &r[..w as usize * 4])
            .copied()
            .collect();
        Ok(Some(Screenshot {
            width: w,
            height: h,
            rgba8,
        }))
    }

    /// Applies the script's commands up to the next `frame N` not reached.
    fn run_script(&mut self) {
        while let Some(&a) = self.script.last() {
            match a {
                Action::AfterFrame(n) if self.frames < n => return,
                Action::Resize([w, h]) => {
                    // Applied now or announced by a Resized event; the
                    // frame reads the size from the window either way.
                    let _ = self.window.request_inner_size(PhysicalSize::new(w, h));
                }
                _ => self.quit |= self.state.apply(a),
            }
            self.script.pop();
        }
    }

    /// Refreshes the overlay and the title when the settings changed, and
    /// the frame time at most every [`TEXT_REFRESH`].
    fn update_text(&mut self) -> Result<(), Error> {
        let now = Instant::now();
        if self.shown_at.is_none_or(|t| now - t >= TEXT_REFRESH) {
            self.shown_ms = self.frame_ms;
            self.shown_at = Some(now);
        }
        let lines = self.state.status_lines(self.shown_ms);
        self.presenter.set_text(&self.ctx, &lines)?;
        let title = format!("{}: {}", self.title, lines.join(" | "));
        if title != self.window.title() {
            self.window.set_title(&title);
        }
        Ok(())
    }
}
