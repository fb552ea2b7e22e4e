//! `--raster PROFILE`, for every command that rasterizes.

use occsim_traces::raster::RasterProfile;

#[derive(clap::Args, Clone, Copy, Debug)]
pub struct RasterArgs {
    /// The rasterizer's arithmetic: `llvmpipe` (Mesa 22.3 llvmpipe bit for bit, into a
    /// framebuffer object), `llvmpipe-window` (the same into a window-system framebuffer, y
    /// mirrored) or `exact` (occsim's exact rasterizer: guard band, exact depth).
    #[arg(long = "raster", value_name = "PROFILE", default_value = "llvmpipe",
          value_parser = RasterProfile::from_name)]
    pub profile: RasterProfile,
}
