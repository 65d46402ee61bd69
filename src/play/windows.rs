//! The node's outputs as windows: one borderless window per output (fullscreen on a named
//! monitor, or at a rectangle), one wgpu device presenting to all of them, each window redrawn
//! when its picture changes or the system asks. Presentation is FIFO, the mode every surface
//! offers and the one that never tears; the pictures themselves change only between frames.
//!
//! Keys: `b` mutes every output to black and back (the picture is kept); `o` puts the
//! operator's overlay on every output and takes it off (`--overlay` starts with it): the
//! channel's id large, what it shows, its rates and the time, redrawn every second. Closing a
//! window, SIGTERM or Ctrl-C (the `stop` flag) ends the node.

use super::{Deliver, Output, Place, Rate, Status, Stop, Update, overlay, overlay_lines, stopping};
use crate::error::{Error, Result};
use crate::gpu::Gpu;
use crate::gpu::show::{Picture, ShowPass};
use crate::raster::Raster;
use std::sync::Arc;
use std::time::{Duration, Instant};
use winit::application::ApplicationHandler;
use winit::dpi::{PhysicalPosition, PhysicalSize};
use winit::event::{ElementState, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop, EventLoopProxy};
use winit::keyboard::Key;
use winit::window::{Fullscreen, Window, WindowId};

impl Deliver for EventLoopProxy<Update> {
    fn deliver(&self, u: Update) -> bool {
        self.send_event(u).is_ok()
    }
}

/// How the windows start.
pub struct Options {
    /// The GPU adapter to use, by a part of its name or backend.
    pub adapter: Option<String>,
    /// Whether the operator's overlay is on from the start.
    pub overlay: bool,
}

/// Opens the display; `start` is then given a sender for the pictures (it starts whatever
/// makes them) before the windows open and the loop runs until `stop`.
pub fn run(
    outputs: Vec<Output>,
    status: Arc<Status>,
    stop: Stop,
    options: Options,
    start: impl FnOnce(EventLoopProxy<Update>),
) -> Result<()> {
    let event_loop = EventLoop::<Update>::with_user_event()
        .build()
        .map_err(|e| {
            Error::invalid(
                "display",
                format!("cannot open one ({e}); is DISPLAY set, or use --headless"),
            )
        })?;
    start(event_loop.create_proxy());
    let mut app = App {
        outputs,
        status,
        stop,
        adapter: options.adapter,
        screens: Vec::new(),
        gpu: None,
        pass: None,
        black: false,
        overlay: options.overlay,
        overlaid: Instant::now(),
        rate: Rate::default(),
        failed: None,
    };
    event_loop
        .run_app(&mut app)
        .map_err(|e| Error::invalid("display", e.to_string()))?;
    match app.failed {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

/// One output's window and what it shows.
struct Screen {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    picture: Option<Picture>,
    /// The picture as it came, kept for the overlay to be drawn over.
    image: Option<Raster<[u8; 4]>>,
    /// The tag of a new picture, reported once it has been presented.
    tag: Option<String>,
}

struct App {
    outputs: Vec<Output>,
    status: Arc<Status>,
    stop: Stop,
    adapter: Option<String>,
    screens: Vec<Screen>,
    gpu: Option<Gpu>,
    pass: Option<ShowPass>,
    black: bool,
    overlay: bool,
    /// When the overlay was last drawn.
    overlaid: Instant,
    rate: Rate,
    /// Why the loop ended early, if it did.
    failed: Option<Error>,
}

impl App {
    fn open(&mut self, event_loop: &ActiveEventLoop) -> Result<()> {
        let monitors: Vec<_> = event_loop.available_monitors().collect();
        let mut windows = Vec::new();
        for o in &self.outputs {
            let mut attrs = Window::default_attributes()
                .with_title(format!("omniwarp {}", o.channel))
                .with_decorations(false);
            attrs = match &o.place {
                Some(Place::Window { x, y, w, h }) => attrs
                    .with_position(PhysicalPosition::new(*x, *y))
                    .with_inner_size(PhysicalSize::new(*w, *h)),
                Some(Place::Monitor(name)) => {
                    let m = monitors
                        .iter()
                        .find(|m| m.name().as_deref() == Some(name.as_str()))
                        .ok_or_else(|| {
                            let names: Vec<String> =
                                monitors.iter().filter_map(|m| m.name()).collect();
                            Error::invalid(
                                "output",
                                format!(
                                    "no monitor `{name}`; this display has {}",
                                    names.join(", ")
                                ),
                            )
                        })?;
                    attrs.with_fullscreen(Some(Fullscreen::Borderless(Some(m.clone()))))
                }
                None => attrs.with_fullscreen(Some(Fullscreen::Borderless(None))),
            };
            let window = event_loop
                .create_window(attrs)
                .map_err(|e| Error::invalid("output", format!("{}: {e}", o.channel)))?;
            windows.push(Arc::new(window));
        }
        let display = Box::new(event_loop.owned_display_handle());
        let instance = wgpu::Instance::new(
            wgpu::InstanceDescriptor::new_with_display_handle_from_env(display),
        );
        let mut surfaces = Vec::new();
        for (w, o) in windows.iter().zip(&self.outputs) {
            let s = instance
                .create_surface(w.clone())
                .map_err(|e| Error::invalid("output", format!("{}: {e}", o.channel)))?;
            surfaces.push(s);
        }
        let gpu =
            Gpu::on(&instance, self.adapter.as_deref(), surfaces.first())?.ok_or_else(|| {
                Error::invalid(
                    "adapter",
                    "none can present to these windows (install mesa-vulkan-drivers for the \
                     CPU's), or use --headless",
                )
            })?;
        eprintln!("presenting through {}", gpu.describe());
        for ((window, surface), o) in windows.into_iter().zip(surfaces).zip(&self.outputs) {
            let caps = surface.get_capabilities(&gpu.adapter);
            // A plain (not sRGB) format: the pictures are already encoded, and must reach the
            // projector as they are.
            let format = caps
                .formats
                .iter()
                .copied()
                .find(|f| !f.is_srgb())
                .ok_or_else(|| {
                    Error::invalid(
                        "output",
                        format!("{}: the surface offers only sRGB formats", o.channel),
                    )
                })?;
            let size = window.inner_size();
            let config = wgpu::SurfaceConfiguration {
                usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
                format,
                width: size.width.max(1),
                height: size.height.max(1),
                present_mode: wgpu::PresentMode::Fifo,
                desired_maximum_frame_latency: 2,
                alpha_mode: caps.alpha_modes[0],
                view_formats: vec![],
                color_space: wgpu::SurfaceColorSpace::Auto,
            };
            surface.configure(&gpu.device, &config);
            self.screens.push(Screen {
                window,
                surface,
                config,
                picture: None,
                image: None,
                tag: None,
            });
        }
        self.pass = Some(ShowPass::new(&gpu));
        self.gpu = Some(gpu);
        Ok(())
    }

    /// Uploads `image` (with the overlay over it when it is on) as output `i`'s picture, tagged
    /// `tag` when it is a new one, and asks for a redraw. A picture that cannot be uploaded
    /// (larger than this adapter takes) is reported and replaces nothing.
    fn show(&mut self, i: usize, image: Raster<[u8; 4]>, tag: Option<String>) {
        let (Some(gpu), Some(pass)) = (&self.gpu, &self.pass) else {
            return;
        };
        let uploaded = if self.overlay {
            let mut state = self.status.get();
            if tag.is_some() {
                state.outputs[i].1 = tag.clone();
            }
            let lines = overlay_lines(&state, i);
            pass.upload(gpu, &overlay(&image, &self.outputs[i].channel, &lines))
        } else {
            pass.upload(gpu, &image)
        };
        match uploaded {
            Ok(picture) => {
                let screen = &mut self.screens[i];
                screen.picture = Some(picture);
                screen.image = Some(image);
                if tag.is_some() {
                    screen.tag = tag;
                }
                screen.window.request_redraw();
            }
            Err(e) => {
                if tag.is_none() {
                    // A redraw of the picture already shown: it stays the one to draw over.
                    self.screens[i].image = Some(image);
                }
                let e = format!("{}: {e}; the picture shown stays", self.outputs[i].channel);
                eprintln!("{e}");
                self.status.update(true, |s| s.error = Some(e));
            }
        }
    }

    /// Draws output `i`'s picture again (the overlay turned on or off, or redrawn).
    fn refresh(&mut self, i: usize) {
        if let Some(image) = self.screens[i].image.take() {
            self.show(i, image, None);
        }
    }

    fn redraw(&mut self, i: usize) {
        let (Some(gpu), Some(pass)) = (&self.gpu, &mut self.pass) else {
            return;
        };
        let screen = &mut self.screens[i];
        let Some(picture) = &screen.picture else {
            return;
        };
        let frame = match screen.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(f)
            | wgpu::CurrentSurfaceTexture::Suboptimal(f) => f,
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                screen.surface.configure(&gpu.device, &screen.config);
                self.status.update(false, |s| s.dropped += 1);
                screen.window.request_redraw();
                return;
            }
            _ => {
                self.status.update(false, |s| s.dropped += 1);
                screen.window.request_redraw();
                return;
            }
        };
        let view = frame
            .texture
            .create_view(&wgpu::TextureViewDescriptor::default());
        let size = (screen.config.width, screen.config.height);
        pass.draw(
            gpu,
            picture,
            self.black,
            (&view, screen.config.format, size),
        );
        screen.window.pre_present_notify();
        gpu.queue.present(frame);
        let fps = self.rate.tick(Instant::now());
        let tag = screen.tag.take();
        let channel = &self.outputs[i].channel;
        if let Some(t) = &tag {
            println!("showing {channel} {t}");
        }
        self.status.update(tag.is_some(), |s| {
            let o = &mut s.outputs[i];
            if let Some(t) = tag {
                o.1 = Some(t);
            }
            o.2 += 1;
            s.fps = fps;
        });
    }
}

impl ApplicationHandler<Update> for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if !self.screens.is_empty() {
            return;
        }
        if let Err(e) = self.open(event_loop) {
            self.failed = Some(e);
            event_loop.exit();
        }
    }

    fn user_event(&mut self, event_loop: &ActiveEventLoop, event: Update) {
        match event {
            Update::Picture(p) => {
                if p.output < self.screens.len() {
                    self.show(p.output, p.image, Some(p.tag));
                }
            }
            Update::Error(e) => {
                eprintln!("{e}");
                self.status.update(true, |s| s.error = Some(e));
            }
        }
        if stopping(&self.stop) {
            event_loop.exit();
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, id: WindowId, event: WindowEvent) {
        let Some(i) = self.screens.iter().position(|s| s.window.id() == id) else {
            return;
        };
        match event {
            WindowEvent::RedrawRequested => self.redraw(i),
            WindowEvent::Resized(size) => {
                if let Some(gpu) = &self.gpu {
                    let s = &mut self.screens[i];
                    s.config.width = size.width.max(1);
                    s.config.height = size.height.max(1);
                    s.surface.configure(&gpu.device, &s.config);
                    s.window.request_redraw();
                }
            }
            WindowEvent::KeyboardInput { event, .. }
                if event.state == ElementState::Pressed && !event.repeat =>
            {
                let Key::Character(c) = &event.logical_key else {
                    return;
                };
                if c.eq_ignore_ascii_case("b") {
                    self.black = !self.black;
                    let black = self.black;
                    self.status.update(true, |s| s.black = black);
                    for s in &self.screens {
                        s.window.request_redraw();
                    }
                } else if c.eq_ignore_ascii_case("o") {
                    self.overlay = !self.overlay;
                    self.overlaid = Instant::now();
                    for i in 0..self.screens.len() {
                        self.refresh(i);
                    }
                }
            }
            WindowEvent::CloseRequested => event_loop.exit(),
            _ => {}
        }
    }

    fn about_to_wait(&mut self, event_loop: &ActiveEventLoop) {
        if stopping(&self.stop) {
            event_loop.exit();
            return;
        }
        if self.overlay && self.overlaid.elapsed() >= Duration::from_secs(1) {
            self.overlaid = Instant::now();
            for i in 0..self.screens.len() {
                self.refresh(i);
            }
        }
        // Woken at least this often to see the stop flag and redraw the overlay; pictures wake
        // it themselves.
        event_loop.set_control_flow(ControlFlow::WaitUntil(
            Instant::now() + Duration::from_millis(100),
        ));
    }
}
