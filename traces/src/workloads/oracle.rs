//! The full render a culling driver is judged against: every object drawn, then each
//! object's visible pixels counted.

use super::{Walk, WorkloadError, WorkloadScene};
use crate::geometry::to_clip;
use crate::golden::{Discard, GoldenModel};
use crate::query::{QueryMode, QuerySpec, BRIEF_RECORD_ENTRIES};
use crate::scene::Command;
use crate::state::{DepthFunc, Rect};

/// For frame `frame` of `walk`: per object, the pixels where it is visible in a render of
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
    let mut golden = GoldenModel::new(walk.width, walk.height);
    let mut run = |command: Command| golden.execute(&command, &mut Discard);
    for command in [
        Command::Clear,
        Command::Cull(true),
        Command::DepthTest(true),
        Command::DepthFunc(DepthFunc::Lequal),
        Command::DepthMask(true),
    ] {
        run(command);
    }
    let draw = |run: &mut dyn FnMut(Command) -> Option<crate::query::QueryResult>,
                object: usize| {
        for triangle in &scene.objects[object].triangles {
            run(Command::Tri(
                triangle.map(|p| to_clip(&view.view_projection, p)),
            ));
        }
    };
    for object in 0..scene.objects.len() {
        draw(&mut run, object);
    }
    run(Command::DepthMask(false));
    let mut visible = Vec::with_capacity(scene.objects.len());
    for object in 0..scene.objects.len() {
        run(Command::Begin(QuerySpec {
            id: object as u32,
            mode: QueryMode::Samples,
            buffer_entries: BRIEF_RECORD_ENTRIES,
            tiles: vec![Rect::new(0, 0, walk.width, walk.height)],
        }));
        draw(&mut run, object);
        visible.push(run(Command::End).map_or(0, |result| result.value()));
    }
    Ok(visible)
}
