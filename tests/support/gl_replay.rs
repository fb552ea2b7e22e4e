//! Replays a scene through Mesa's llvmpipe (OpenGL over a surfaceless EGL context) and reads
//! back every query's counts, for the differential check against the golden model.
//!
//! Setup: EGL_PLATFORM_SURFACELESS_MESA display, desktop GL context, and either a framebuffer
//! object with a 24-bit depth renderbuffer and an RGBA8 colour one ([`Target::Fbo`]) or a
//! pbuffer surface with a 24-bit depth buffer ([`Target::Pbuffer`], a window-system
//! framebuffer: Mesa mirrors its y); colour writes off, viewport 0,0,W,H, depth range 0..1, a
//! pass-through vertex shader fed clip coordinates.
//!
//! Every run of consecutive `tri` commands is one `glDrawArrays` (a draw, as the golden
//! model's rasterizer takes it): any other command flushes the pending triangles first.
//!
//! Mapping of the scene commands:
//! - `samples` / `any`: one `GL_SAMPLES_PASSED` / `GL_ANY_SAMPLES_PASSED` query.
//! - `brief` / `verbose` (occlusion render modes, framebuffer untouched): the commands between
//!   `begin` and `end` are buffered and replayed once per tile, each pass a
//!   `GL_SAMPLES_PASSED` query with depth writes masked and the scissor set to
//!   tile ∩ scene scissor, which gives the tile's NOHC. A `clear` inside such a query would
//!   be replayed once per tile, so scenes must not put one there.
//! - `clear` ignores scissor and depth mask (as the golden model's `Event::Clear`), so the
//!   replay lifts both around `glClear`.
//! - `begin_conditional ID` on a `samples` or `any` query is
//!   `glBeginConditionalRender(query, GL_QUERY_WAIT)` on that query's GL object (kept until
//!   the id is reused); on a `brief` or `verbose` query, which has no GL object of its own,
//!   the replay skips the draws itself when Mesa's per-tile counts were all zero.
//! - `wait`, `host` and `swap` end the pending draw and change nothing else.
//!
//! Set `LIBGL_ALWAYS_SOFTWARE=1`, `GALLIUM_DRIVER=llvmpipe` (done by [`GlReplay::new`]) before
//! the first EGL call; [`GlReplay::new`] sets `LP_NUM_THREADS=0` (no rasterizer threads)
//! unless it is set, and benchmarks set it to 1.

use glow::HasContext;
use khronos_egl as egl;
use occsim_traces::{Command, QueryMode, Rect, SceneLine};

/// `EGL_PLATFORM_SURFACELESS_MESA` (EGL_MESA_platform_surfaceless).
const PLATFORM_SURFACELESS_MESA: egl::Enum = 0x31DD;

/// One query's counts as Mesa reports them.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct GlQueryCounts {
    pub id: u32,
    pub mode: QueryMode,
    /// `samples`: one entry, the passing count; `any`: one entry, 0 or 1; `brief` and
    /// `verbose`: the passing count (NOHC) of each tile, in the query's order.
    pub counts: Vec<u64>,
}

/// What llvmpipe renders into.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Target {
    /// A framebuffer object (y up): the `llvmpipe` profile.
    Fbo,
    /// A pbuffer, a window-system framebuffer (y mirrored): the `llvmpipe-window` profile.
    Pbuffer,
}

/// A live llvmpipe context rendering into a `width` x `height` framebuffer.
pub struct GlReplay {
    egl: egl::DynamicInstance<egl::EGL1_5>,
    display: egl::Display,
    context: egl::Context,
    surface: Option<egl::Surface>,
    gl: glow::Context,
    width: u32,
    height: u32,
    vertex_buffer: glow::Buffer,
    /// Clip coordinates of triangles waiting to be drawn in one `glDrawArrays`.
    pending: Vec<f32>,
    /// What conditional rendering can read of each ended query.
    ended: std::collections::HashMap<u32, EndedQuery>,
    /// Inside a conditional on a per-tile query that passed nothing: draws are dropped.
    skip_draws: bool,
    /// Inside a GL conditional render.
    gl_conditional: bool,
    begin_conditional_render: unsafe extern "system" fn(u32, u32),
    end_conditional_render: unsafe extern "system" fn(),
}

/// An ended query, as `begin_conditional` sees it.
enum EndedQuery {
    /// A samples or any query's GL object.
    Gl(glow::Query),
    /// A per-tile query: whether any tile passed a fragment.
    PerTile(bool),
}

/// The open query while a scene is replayed.
enum OpenQuery {
    /// A GL query object counting directly.
    Direct {
        id: u32,
        mode: QueryMode,
        query: glow::Query,
    },
    /// An occlusion render mode query: its commands, replayed per tile at `end`.
    PerTile {
        id: u32,
        mode: QueryMode,
        tiles: Vec<Rect>,
        commands: Vec<Command>,
        state_at_begin: GlState,
    },
}

/// The scene state the replay needs to restore between per-tile passes.
#[derive(Clone, Copy)]
struct GlState {
    depth_mask: bool,
    scissor: Option<Rect>,
    depth_func: u32,
    depth_test: bool,
    cull: bool,
}

impl GlReplay {
    /// Load libEGL, make a surfaceless llvmpipe context current on this thread and set up
    /// a framebuffer object. `Err` says why when EGL or the context is unavailable.
    pub fn new(width: u32, height: u32) -> Result<GlReplay, String> {
        GlReplay::with_target(Target::Fbo, width, height)
    }

    /// As [`GlReplay::new`], rendering into `target`.
    pub fn with_target(target: Target, width: u32, height: u32) -> Result<GlReplay, String> {
        std::env::set_var("LIBGL_ALWAYS_SOFTWARE", "1");
        std::env::set_var("GALLIUM_DRIVER", "llvmpipe");
        // Rasterize on the calling thread unless told otherwise: the small scenes of the
        // differential test run twice as fast without handing each draw to a worker, and
        // the arithmetic is the same code either way.
        if std::env::var_os("LP_NUM_THREADS").is_none() {
            std::env::set_var("LP_NUM_THREADS", "0");
        }
        // `OCCSIM_LIBEGL` names another libEGL (a missing one exercises the skip path).
        let library = std::env::var("OCCSIM_LIBEGL").unwrap_or_else(|_| "libEGL.so.1".into());
        // SAFETY: loading libEGL; its symbols follow the EGL ABI.
        let egl =
            unsafe { egl::DynamicInstance::<egl::EGL1_5>::load_required_from_filename(&library) }
                .map_err(|e| format!("libEGL not found ({library}: {e})"))?;
        // SAFETY: the surfaceless platform takes no native display.
        let display = unsafe {
            egl.get_platform_display(
                PLATFORM_SURFACELESS_MESA,
                egl::DEFAULT_DISPLAY,
                &[egl::ATTRIB_NONE],
            )
        }
        .map_err(|e| format!("no surfaceless EGL display ({e})"))?;
        egl.initialize(display)
            .map_err(|e| format!("eglInitialize failed ({e})"))?;
        egl.bind_api(egl::OPENGL_API)
            .map_err(|e| format!("eglBindAPI(OPENGL) failed ({e})"))?;
        let config = egl
            .choose_first_config(
                display,
                &[
                    egl::SURFACE_TYPE,
                    egl::PBUFFER_BIT,
                    egl::RENDERABLE_TYPE,
                    egl::OPENGL_BIT,
                    egl::DEPTH_SIZE,
                    if target == Target::Pbuffer { 24 } else { 0 },
                    egl::RED_SIZE,
                    8,
                    egl::NONE,
                ],
            )
            .map_err(|e| format!("eglChooseConfig failed ({e})"))?
            .ok_or("no EGL config on the surfaceless display")?;
        if target == Target::Pbuffer {
            let depth = egl
                .get_config_attrib(display, config, egl::DEPTH_SIZE)
                .map_err(|e| format!("eglGetConfigAttrib failed ({e})"))?;
            if depth != 24 {
                return Err(format!(
                    "the pbuffer config has a {depth}-bit depth buffer, not 24"
                ));
            }
        }
        let context = egl
            .create_context(
                display,
                config,
                None,
                &[
                    egl::CONTEXT_MAJOR_VERSION,
                    3,
                    egl::CONTEXT_MINOR_VERSION,
                    3,
                    egl::NONE,
                ],
            )
            .map_err(|e| format!("eglCreateContext failed ({e})"))?;
        let surface = match target {
            Target::Fbo => None,
            Target::Pbuffer => Some(
                egl.create_pbuffer_surface(
                    display,
                    config,
                    &[
                        egl::WIDTH,
                        width as i32,
                        egl::HEIGHT,
                        height as i32,
                        egl::NONE,
                    ],
                )
                .map_err(|e| format!("eglCreatePbufferSurface failed ({e})"))?,
            ),
        };
        egl.make_current(display, surface, surface, Some(context))
            .map_err(|e| format!("eglMakeCurrent failed ({e})"))?;
        // SAFETY: the context is current on this thread; the loader returns GL entry points.
        let gl = unsafe {
            glow::Context::from_loader_function(|name| {
                egl.get_proc_address(name)
                    .map_or(std::ptr::null(), |f| f as *const _)
            })
        };
        // glow has no wrapper for conditional rendering: load the two entry points (GL 3.0).
        let load = |name: &str| {
            egl.get_proc_address(name)
                .ok_or_else(|| format!("no {name} in libGL"))
        };
        let (begin, end) = (
            load("glBeginConditionalRender")?,
            load("glEndConditionalRender")?,
        );
        // SAFETY: the GL 3.0 signatures of these entry points.
        let (begin_conditional_render, end_conditional_render) = unsafe {
            (
                std::mem::transmute::<extern "system" fn(), unsafe extern "system" fn(u32, u32)>(
                    begin,
                ),
                std::mem::transmute::<extern "system" fn(), unsafe extern "system" fn()>(end),
            )
        };
        // SAFETY: plain GL calls on the current context.
        let vertex_buffer = unsafe { set_up_pipeline(&gl, target, width, height)? };
        Ok(GlReplay {
            egl,
            display,
            context,
            surface,
            gl,
            width,
            height,
            vertex_buffer,
            pending: Vec::new(),
            ended: std::collections::HashMap::new(),
            skip_draws: false,
            gl_conditional: false,
            begin_conditional_render,
            end_conditional_render,
        })
    }

    /// The GL renderer string (to prove llvmpipe is in use).
    pub fn renderer(&self) -> String {
        // SAFETY: a plain GL query on the current context.
        unsafe { self.gl.get_parameter_string(glow::RENDERER) }
    }

    /// Replay a whole scene (the depth buffer starts cleared, state at GL's defaults) and
    /// return every query's counts in the order the queries end.
    pub fn run(&mut self, lines: &[SceneLine]) -> Vec<GlQueryCounts> {
        let mut state = GlState {
            depth_mask: true,
            scissor: None,
            depth_func: glow::LESS,
            depth_test: true,
            cull: false,
        };
        self.apply_state(&state, None);
        self.clear();
        for (_, ended) in std::mem::take(&mut self.ended) {
            if let EndedQuery::Gl(query) = ended {
                // SAFETY: a GL call on the current context; the object is no longer named.
                unsafe { self.gl.delete_query(query) };
            }
        }
        let mut open: Option<OpenQuery> = None;
        let mut results = Vec::new();
        for line in lines {
            let command = &line.command;
            if let Some(OpenQuery::PerTile { commands, .. }) = &mut open {
                if !matches!(command, Command::End) {
                    commands.push(command.clone());
                    update_state(&mut state, command);
                    continue;
                }
            }
            match command {
                Command::Begin(spec) => {
                    self.flush();
                    open = Some(if spec.mode.is_occlusion_render_mode() {
                        OpenQuery::PerTile {
                            id: spec.id,
                            mode: spec.mode,
                            tiles: spec.tiles.clone(),
                            commands: Vec::new(),
                            state_at_begin: state,
                        }
                    } else {
                        let target = match spec.mode {
                            QueryMode::Any => glow::ANY_SAMPLES_PASSED,
                            _ => glow::SAMPLES_PASSED,
                        };
                        // SAFETY: plain GL calls on the current context.
                        let query = unsafe {
                            let query = self.gl.create_query().expect("glGenQueries");
                            self.gl.begin_query(target, query);
                            query
                        };
                        OpenQuery::Direct {
                            id: spec.id,
                            mode: spec.mode,
                            query,
                        }
                    });
                }
                Command::End => {
                    self.flush();
                    match open.take() {
                        Some(OpenQuery::Direct { id, mode, query }) => {
                            let target = match mode {
                                QueryMode::Any => glow::ANY_SAMPLES_PASSED,
                                _ => glow::SAMPLES_PASSED,
                            };
                            // SAFETY: plain GL calls on the current context.
                            let count = unsafe {
                                self.gl.end_query(target);
                                self.gl.get_query_parameter_u32(query, glow::QUERY_RESULT)
                            };
                            self.keep_ended(id, EndedQuery::Gl(query));
                            results.push(GlQueryCounts {
                                id,
                                mode,
                                counts: vec![count as u64],
                            });
                        }
                        Some(OpenQuery::PerTile {
                            id,
                            mode,
                            tiles,
                            commands,
                            state_at_begin,
                        }) => {
                            let counts: Vec<u64> = tiles
                                .iter()
                                .map(|tile| self.count_tile(tile, &commands, state_at_begin))
                                .collect();
                            let passed = counts.iter().any(|&c| c > 0);
                            self.keep_ended(id, EndedQuery::PerTile(passed));
                            results.push(GlQueryCounts { id, mode, counts });
                            self.apply_state(&state, None);
                        }
                        None => {}
                    }
                }
                Command::Tri(vertices) => {
                    for vertex in vertices {
                        self.pending.extend_from_slice(vertex);
                    }
                }
                Command::BeginConditional(id) => {
                    self.flush();
                    match self.ended.get(id) {
                        // SAFETY: a GL call on the current context with a live query object.
                        Some(EndedQuery::Gl(query)) => unsafe {
                            (self.begin_conditional_render)(query.0.get(), glow::QUERY_WAIT);
                            self.gl_conditional = true;
                        },
                        Some(EndedQuery::PerTile(passed)) => self.skip_draws = !passed,
                        None => {}
                    }
                }
                Command::EndConditional => {
                    self.flush();
                    if std::mem::replace(&mut self.gl_conditional, false) {
                        // SAFETY: a GL call on the current context, inside a conditional.
                        unsafe { (self.end_conditional_render)() };
                    }
                    self.skip_draws = false;
                }
                other => {
                    self.flush();
                    if matches!(other, Command::Clear) {
                        self.clear();
                    }
                    update_state(&mut state, other);
                    self.apply_state(&state, None);
                }
            }
        }
        self.flush();
        results
    }

    /// One tile's NOHC: replay the query's commands with writes masked, scissored to the tile.
    fn count_tile(&mut self, tile: &Rect, commands: &[Command], begin_state: GlState) -> u64 {
        let mut state = begin_state;
        self.apply_state(&state, Some(tile));
        // SAFETY: plain GL calls on the current context.
        let query = unsafe {
            let query = self.gl.create_query().expect("glGenQueries");
            self.gl.begin_query(glow::SAMPLES_PASSED, query);
            query
        };
        for command in commands {
            if let Command::Tri(vertices) = command {
                for vertex in vertices {
                    self.pending.extend_from_slice(vertex);
                }
            } else {
                self.flush();
                update_state(&mut state, command);
                self.apply_state(&state, Some(tile));
            }
        }
        self.flush();
        // SAFETY: plain GL calls on the current context.
        unsafe {
            self.gl.end_query(glow::SAMPLES_PASSED);
            let count = self.gl.get_query_parameter_u32(query, glow::QUERY_RESULT);
            self.gl.delete_query(query);
            count as u64
        }
    }

    /// Set GL to `state`; with `tile`, in occlusion render mode: writes off, scissor cut to it.
    fn apply_state(&self, state: &GlState, tile: Option<&Rect>) {
        let gl = &self.gl;
        let viewport = Rect::new(0, 0, self.width, self.height);
        let scissor = match (state.scissor, tile) {
            (None, None) => None,
            (Some(s), None) => Some(s),
            (None, Some(t)) => Some(*t),
            (Some(s), Some(t)) => Some(s.intersect(t)),
        };
        // SAFETY: plain GL calls on the current context.
        unsafe {
            gl.depth_mask(state.depth_mask && tile.is_none());
            gl.depth_func(state.depth_func);
            set_enabled(gl, glow::DEPTH_TEST, state.depth_test);
            set_enabled(gl, glow::CULL_FACE, state.cull);
            match scissor {
                Some(s) => {
                    let s = s.intersect(&viewport);
                    gl.enable(glow::SCISSOR_TEST);
                    gl.scissor(s.x as i32, s.y as i32, s.width as i32, s.height as i32);
                }
                None => gl.disable(glow::SCISSOR_TEST),
            }
        }
    }

    /// Depth := 1 everywhere, whatever the scissor and mask (then the caller restores them).
    fn clear(&self) {
        // SAFETY: plain GL calls on the current context.
        unsafe {
            self.gl.disable(glow::SCISSOR_TEST);
            self.gl.depth_mask(true);
            self.gl.clear_depth_f64(1.0);
            self.gl.clear(glow::DEPTH_BUFFER_BIT);
        }
    }

    /// Keep what conditional rendering needs of query `id`, freeing what it replaces.
    fn keep_ended(&mut self, id: u32, ended: EndedQuery) {
        if let Some(EndedQuery::Gl(old)) = self.ended.insert(id, ended) {
            // SAFETY: a GL call on the current context; the old object is no longer named.
            unsafe { self.gl.delete_query(old) };
        }
    }

    /// Draw the pending triangles in one call, in order (none inside a conditional whose
    /// per-tile query passed nothing).
    fn flush(&mut self) {
        if self.skip_draws {
            self.pending.clear();
        }
        if self.pending.is_empty() {
            return;
        }
        let bytes: Vec<u8> = self.pending.iter().flat_map(|f| f.to_ne_bytes()).collect();
        // SAFETY: plain GL calls on the current context; the buffer holds whole vertices.
        unsafe {
            self.gl
                .bind_buffer(glow::ARRAY_BUFFER, Some(self.vertex_buffer));
            self.gl
                .buffer_data_u8_slice(glow::ARRAY_BUFFER, &bytes, glow::STREAM_DRAW);
            self.gl
                .draw_arrays(glow::TRIANGLES, 0, (self.pending.len() / 4) as i32);
        }
        self.pending.clear();
    }
}

impl Drop for GlReplay {
    fn drop(&mut self) {
        let _ = self.egl.make_current(self.display, None, None, None);
        if let Some(surface) = self.surface {
            let _ = self.egl.destroy_surface(self.display, surface);
        }
        let _ = self.egl.destroy_context(self.display, self.context);
    }
}

/// Track the scene state a command changes (triangles and queries change none).
fn update_state(state: &mut GlState, command: &Command) {
    match command {
        Command::DepthFunc(f) => state.depth_func = gl_depth_func(*f),
        Command::DepthMask(b) => state.depth_mask = *b,
        Command::DepthTest(b) => state.depth_test = *b,
        Command::Cull(b) => state.cull = *b,
        Command::Scissor(s) => state.scissor = *s,
        _ => {}
    }
}

fn gl_depth_func(f: occsim_traces::DepthFunc) -> u32 {
    use occsim_traces::DepthFunc as F;
    match f {
        F::Never => glow::NEVER,
        F::Less => glow::LESS,
        F::Equal => glow::EQUAL,
        F::Lequal => glow::LEQUAL,
        F::Greater => glow::GREATER,
        F::Notequal => glow::NOTEQUAL,
        F::Gequal => glow::GEQUAL,
        F::Always => glow::ALWAYS,
    }
}

unsafe fn set_enabled(gl: &glow::Context, capability: u32, on: bool) {
    if on {
        gl.enable(capability);
    } else {
        gl.disable(capability);
    }
}

/// The framebuffer (for an FBO), shaders, vertex layout and fixed state; returns the vertex
/// buffer.
unsafe fn set_up_pipeline(
    gl: &glow::Context,
    target: Target,
    width: u32,
    height: u32,
) -> Result<glow::Buffer, String> {
    if target == Target::Fbo {
        set_up_framebuffer_object(gl, width, height)?;
    }
    set_up_shaders_and_state(gl, width, height)
}

/// A framebuffer object with a 24-bit depth renderbuffer and an RGBA8 colour one, bound.
unsafe fn set_up_framebuffer_object(
    gl: &glow::Context,
    width: u32,
    height: u32,
) -> Result<(), String> {
    let framebuffer = gl.create_framebuffer()?;
    gl.bind_framebuffer(glow::FRAMEBUFFER, Some(framebuffer));
    let colour = gl.create_renderbuffer()?;
    gl.bind_renderbuffer(glow::RENDERBUFFER, Some(colour));
    gl.renderbuffer_storage(glow::RENDERBUFFER, glow::RGBA8, width as i32, height as i32);
    gl.framebuffer_renderbuffer(
        glow::FRAMEBUFFER,
        glow::COLOR_ATTACHMENT0,
        glow::RENDERBUFFER,
        Some(colour),
    );
    let depth = gl.create_renderbuffer()?;
    gl.bind_renderbuffer(glow::RENDERBUFFER, Some(depth));
    gl.renderbuffer_storage(
        glow::RENDERBUFFER,
        glow::DEPTH_COMPONENT24,
        width as i32,
        height as i32,
    );
    gl.framebuffer_renderbuffer(
        glow::FRAMEBUFFER,
        glow::DEPTH_ATTACHMENT,
        glow::RENDERBUFFER,
        Some(depth),
    );
    let status = gl.check_framebuffer_status(glow::FRAMEBUFFER);
    if status != glow::FRAMEBUFFER_COMPLETE {
        return Err(format!("framebuffer incomplete (0x{status:x})"));
    }
    Ok(())
}

/// Shaders, vertex layout and fixed state; returns the vertex buffer.
unsafe fn set_up_shaders_and_state(
    gl: &glow::Context,
    width: u32,
    height: u32,
) -> Result<glow::Buffer, String> {
    let program = gl.create_program()?;
    for (kind, source) in [
        (
            glow::VERTEX_SHADER,
            "#version 130\nin vec4 clip_position;\nvoid main() { gl_Position = clip_position; }\n",
        ),
        (
            glow::FRAGMENT_SHADER,
            "#version 130\nout vec4 colour;\nvoid main() { colour = vec4(1.0); }\n",
        ),
    ] {
        let shader = gl.create_shader(kind)?;
        gl.shader_source(shader, source);
        gl.compile_shader(shader);
        if !gl.get_shader_compile_status(shader) {
            return Err(format!(
                "shader compile failed: {}",
                gl.get_shader_info_log(shader)
            ));
        }
        gl.attach_shader(program, shader);
    }
    gl.bind_attrib_location(program, 0, "clip_position");
    gl.link_program(program);
    if !gl.get_program_link_status(program) {
        return Err(format!(
            "program link failed: {}",
            gl.get_program_info_log(program)
        ));
    }
    gl.use_program(Some(program));

    let vertex_array = gl.create_vertex_array()?;
    gl.bind_vertex_array(Some(vertex_array));
    let vertex_buffer = gl.create_buffer()?;
    gl.bind_buffer(glow::ARRAY_BUFFER, Some(vertex_buffer));
    gl.enable_vertex_attrib_array(0);
    gl.vertex_attrib_pointer_f32(0, 4, glow::FLOAT, false, 16, 0);

    gl.viewport(0, 0, width as i32, height as i32);
    gl.depth_range_f64(0.0, 1.0);
    gl.color_mask(false, false, false, false);
    gl.cull_face(glow::BACK);
    gl.front_face(glow::CCW);
    gl.disable(glow::MULTISAMPLE);
    Ok(vertex_buffer)
}
