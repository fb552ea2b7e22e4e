//! The full render a culling driver is judged against: every object drawn, then each
//! object's visible pixels counted.

use super::{Walk, WorkloadError, WorkloadScene};
use crate::geometry::to_clip;
use crate::golden::{infallible, Discard, GoldenModel};
use crate::query::{QueryMode, QuerySpec, BRIEF_RECORD_ENTRIES};
use crate::scene::Command;
use crate::state::{DepthFunc, Rect};

/// For frame `frame` of `walk` (moving objects in that frame's poses): per object, the pixels where it is visible in a render of
/// the whole scene without culling. Every object is drawn (back faces culled, LEQUAL, as the
/// drivers draw), then each object is drawn again inside a samples query with depth writes
/// off: a fragment passes exactly where the object's depth equals the final depth.
pub fn full_render_visible_pixels(
    scene: &WorkloadScene,
    frame: u32,
    walk: &Walk,
) -> Result<Vec<u64>, WorkloadError> {
    walk.validate()?;
    let view = scene.frame_view(frame, walk);
    let scene = scene.posed(frame);
    let mut golden = GoldenModel::try_with_profile(walk.width, walk.height, walk.raster)?;
    for command in [
        Command::Clear,
        Command::Cull(true),
        Command::DepthTest(true),
        Command::DepthFunc(DepthFunc::Lequal),
        Command::DepthMask(true),
    ] {
        infallible(golden.execute(&command, &mut Discard));
    }
    // Each object a draw of its own, as the drivers draw them.
    let draw = |golden: &mut GoldenModel, object: usize| {
        for triangle in &scene.objects[object].triangles {
            let clip = triangle.map(|p| to_clip(&view.view_projection, p));
            infallible(golden.execute(&Command::Tri(clip), &mut Discard));
        }
        infallible(golden.execute(&Command::EndDraw, &mut Discard));
    };
    for object in 0..scene.objects.len() {
        draw(&mut golden, object);
    }
    infallible(golden.execute(&Command::DepthMask(false), &mut Discard));
    let mut visible = Vec::with_capacity(scene.objects.len());
    for object in 0..scene.objects.len() {
        infallible(golden.execute(
            &Command::Begin(QuerySpec {
                id: object as u32,
                mode: QueryMode::Samples,
                buffer_entries: BRIEF_RECORD_ENTRIES,
                tiles: vec![Rect::new(0, 0, walk.width, walk.height)],
            }),
            &mut Discard,
        ));
        draw(&mut golden, object);
        let result = infallible(golden.execute(&Command::End, &mut Discard));
        visible.push(result.map_or(0, |result| result.value()));
    }
    Ok(visible)
}
