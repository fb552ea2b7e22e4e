//! Fixed-function state that decides which fragments exist and which pass.

use serde::{Deserialize, Serialize};

/// Largest viewport side in pixels; the rasterizer's integer ranges are proven for it.
pub const MAX_VIEWPORT_SIDE: u32 = 16384;

/// Depth comparison, as `glDepthFunc`: the incoming fragment's depth is the left operand.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DepthFunc {
    Never,
    Less,
    Equal,
    Lequal,
    Greater,
    Notequal,
    Gequal,
    Always,
}

impl DepthFunc {
    pub const ALL: [DepthFunc; 8] = [
        DepthFunc::Never,
        DepthFunc::Less,
        DepthFunc::Equal,
        DepthFunc::Lequal,
        DepthFunc::Greater,
        DepthFunc::Notequal,
        DepthFunc::Gequal,
        DepthFunc::Always,
    ];

    /// Does a fragment at depth `incoming` pass against the stored depth `stored`?
    #[inline(always)]
    pub fn passes(self, incoming: u32, stored: u32) -> bool {
        match self {
            DepthFunc::Never => false,
            DepthFunc::Less => incoming < stored,
            DepthFunc::Equal => incoming == stored,
            DepthFunc::Lequal => incoming <= stored,
            DepthFunc::Greater => incoming > stored,
            DepthFunc::Notequal => incoming != stored,
            DepthFunc::Gequal => incoming >= stored,
            DepthFunc::Always => true,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            DepthFunc::Never => "never",
            DepthFunc::Less => "less",
            DepthFunc::Equal => "equal",
            DepthFunc::Lequal => "lequal",
            DepthFunc::Greater => "greater",
            DepthFunc::Notequal => "notequal",
            DepthFunc::Gequal => "gequal",
            DepthFunc::Always => "always",
        }
    }

    pub fn from_name(name: &str) -> Option<DepthFunc> {
        DepthFunc::ALL.into_iter().find(|f| f.name() == name)
    }

    /// A 3-bit code for compact encodings.
    pub fn code(self) -> u8 {
        DepthFunc::ALL.iter().position(|&f| f == self).unwrap_or(0) as u8
    }

    pub fn from_code(code: u8) -> Option<DepthFunc> {
        DepthFunc::ALL.get(code as usize).copied()
    }
}

/// A pixel rectangle in window coordinates (GL convention: origin bottom-left, y up).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Rect {
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
}

impl Rect {
    pub fn new(x: u32, y: u32, width: u32, height: u32) -> Rect {
        Rect {
            x,
            y,
            width,
            height,
        }
    }

    /// Does the pixel (px, py) lie inside?
    #[inline(always)]
    pub fn contains(&self, px: u32, py: u32) -> bool {
        px.wrapping_sub(self.x) < self.width && py.wrapping_sub(self.y) < self.height
    }

    /// The intersection with `other`, which may be empty (zero width or height).
    pub fn intersect(&self, other: &Rect) -> Rect {
        let x0 = self.x.max(other.x);
        let y0 = self.y.max(other.y);
        let x1 = (self.x as u64 + self.width as u64).min(other.x as u64 + other.width as u64);
        let y1 = (self.y as u64 + self.height as u64).min(other.y as u64 + other.height as u64);
        Rect {
            x: x0,
            y: y0,
            width: x1.saturating_sub(x0 as u64) as u32,
            height: y1.saturating_sub(y0 as u64) as u32,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.width == 0 || self.height == 0
    }

    pub fn area(&self) -> u64 {
        self.width as u64 * self.height as u64
    }
}

/// The per-fragment and rasterization state a draw sees.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct RenderState {
    /// Framebuffer (and viewport) width in pixels.
    pub width: u32,
    /// Framebuffer (and viewport) height in pixels.
    pub height: u32,
    pub depth_func: DepthFunc,
    /// Depth writes enabled (`glDepthMask`).
    pub depth_mask: bool,
    /// Depth test enabled; when off every fragment passes and depth is never written (GL).
    pub depth_test: bool,
    /// Cull back faces (clockwise in window coordinates).
    pub cull_back: bool,
    /// Scissor rectangle, if enabled.
    pub scissor: Option<Rect>,
}

impl RenderState {
    /// GL's initial state for a `width` x `height` framebuffer.
    pub fn new(width: u32, height: u32) -> RenderState {
        RenderState {
            width,
            height,
            depth_func: DepthFunc::Less,
            depth_mask: true,
            depth_test: true,
            cull_back: false,
            scissor: None,
        }
    }

    /// Apply a state-change event (depth function, mask, test, culling, scissor); false when
    /// the event changes no state here. The one place every replayer follows the state.
    pub fn apply(&mut self, event: &crate::event::Event) -> bool {
        use crate::event::Event;
        match *event {
            Event::DepthFunc(f) => self.depth_func = f,
            Event::DepthMask(b) => self.depth_mask = b,
            Event::DepthTest(b) => self.depth_test = b,
            Event::Cull(b) => self.cull_back = b,
            Event::Scissor(s) => self.scissor = s,
            _ => return false,
        }
        true
    }

    pub fn viewport(&self) -> Rect {
        Rect::new(0, 0, self.width, self.height)
    }

    /// The pixels a fragment may occupy: the viewport, cut by the scissor.
    pub fn raster_bounds(&self) -> Rect {
        match self.scissor {
            Some(s) => self.viewport().intersect(&s),
            None => self.viewport(),
        }
    }
}
