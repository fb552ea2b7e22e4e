//! Walkthrough workloads end to end: determinism, conservative culling against a full
//! render, culling that pays, and clear errors for bad options.

use occsim_traces::golden::Discard;
use occsim_traces::raster::RasterProfile;
use occsim_traces::state::RenderState;
use occsim_traces::workloads::{
    city, collision_oracle, forest, full_render_visible_pixels, generate, load_obj, traffic,
    CameraPath, CityOptions, DriverKind, DriverOptions, ForestOptions, GridVariant, ObjOptions,
    TrafficOptions, Walk, WorkloadScene, MAX_WALK_FRAMES,
};
use occsim_traces::Event;

fn small_city() -> WorkloadScene {
    city(&CityOptions {
        blocks: 4,
        detail: 1,
        seed: 5,
    })
}

/// The small city with two cars round each block, moving every frame.
fn small_traffic() -> WorkloadScene {
    traffic(&TrafficOptions {
        city: CityOptions {
            blocks: 4,
            detail: 1,
            seed: 5,
        },
        cars_per_block: 2,
    })
}

fn small_forest() -> WorkloadScene {
    forest(&ForestOptions {
        trees: 150,
        detail: 6,
        seed: 9,
    })
}

const WALK: Walk = Walk {
    frames: 5,
    width: 160,
    height: 120,
    raster: RasterProfile::Llvmpipe,
};

/// Every driver configuration that must never cull a visible object.
fn conservative_drivers() -> Vec<DriverOptions> {
    let mut quadtree = DriverOptions::new(DriverKind::Hierarchical);
    quadtree.quadtree_levels = 2;
    let mut coarse_grid = DriverOptions::new(DriverKind::LazyGrid);
    coarse_grid.grid_cell_pixels = 48;
    let mut all: Vec<DriverOptions> = DriverKind::ALL
        .into_iter()
        .map(DriverOptions::new)
        .collect();
    all.push(quadtree);
    all.push(coarse_grid);
    for kind in [DriverKind::LazyGrid, DriverKind::BusyGrid] {
        let mut occlusion_buffer = DriverOptions::new(kind);
        occlusion_buffer.grid_variant = GridVariant::OcclusionBuffer;
        all.push(occlusion_buffer);
    }
    let mut flat = DriverOptions::new(DriverKind::DynamicGrid);
    flat.flat_grid = true;
    all.push(flat);
    let mut fine = DriverOptions::new(DriverKind::DynamicGrid);
    fine.dynamic_grid_resolution = 128;
    all.push(fine);
    assert!(all.iter().all(DriverOptions::is_conservative));
    all
}

/// Two walks of scenes built alike with `driver` give the same events and statistics.
fn check_reproducible(make_scene: fn() -> WorkloadScene, driver: &DriverOptions) {
    let mut first: Vec<Event> = Vec::new();
    let mut second: Vec<Event> = Vec::new();
    let a = generate(&make_scene(), driver, &WALK, &mut first).unwrap();
    let b = generate(&make_scene(), driver, &WALK, &mut second).unwrap();
    assert!(first == second, "{}: event streams differ", driver.label());
    assert_eq!(a.frames, b.frames, "{}", driver.label());
    assert!(
        first.iter().any(|e| matches!(e, Event::Fragment(_))),
        "{}: no fragments",
        driver.label()
    );
}

#[test]
fn the_same_options_give_the_same_events() {
    for driver in conservative_drivers() {
        check_reproducible(small_city, &driver);
    }
    // Moving cars too: their poses depend on the seed and the frame alone.
    for kind in [DriverKind::Frustum, DriverKind::DynamicGrid] {
        check_reproducible(small_traffic, &DriverOptions::new(kind));
    }
}

/// Whether `event` sets one piece of the render state: what `RenderState::apply` takes,
/// the one list of them.
fn sets_state(event: &Event) -> bool {
    RenderState::new(1, 1).apply(event)
}

#[test]
fn every_frame_starts_with_one_clear_and_the_whole_state() {
    // Every driver, on the forest and on the city: a frame is the events up to its `Swap`.
    for (scene, name) in [(small_forest(), "forest"), (small_city(), "city")] {
        for kind in DriverKind::ALL {
            let mut events: Vec<Event> = Vec::new();
            generate(&scene, &DriverOptions::new(kind), &WALK, &mut events).unwrap();
            let label = format!("{} on the {name}", kind.name());
            assert_eq!(events.last(), Some(&Event::Swap), "{label}");
            let frames: Vec<&[Event]> = events[..events.len() - 1]
                .split(|e| matches!(e, Event::Swap))
                .collect();
            assert_eq!(frames.len(), WALK.frames as usize, "{label}");
            for (frame, events) in frames.iter().enumerate() {
                let clears = events.iter().filter(|e| matches!(e, Event::Clear)).count();
                assert_eq!(clears, 1, "{label}, frame {frame}");
                assert_eq!(
                    events.first(),
                    Some(&Event::Clear),
                    "{label}, frame {frame}"
                );
                // Then each of the five pieces of state, once, before anything else.
                let state: Vec<std::mem::Discriminant<Event>> = events[1..]
                    .iter()
                    .take_while(|e| sets_state(e))
                    .map(std::mem::discriminant)
                    .collect();
                let kinds: std::collections::BTreeSet<String> =
                    state.iter().map(|d| format!("{d:?}")).collect();
                assert_eq!((state.len(), kinds.len()), (5, 5), "{label}, frame {frame}");
            }
        }
    }
}

/// Per frame, each object's visible pixels in the full render.
fn full_renders(scene: &WorkloadScene, walk: &Walk) -> Vec<Vec<u64>> {
    let full: Vec<Vec<u64>> = (0..walk.frames)
        .map(|frame| full_render_visible_pixels(scene, frame, walk).unwrap())
        .collect();
    let visible_objects: usize = full
        .iter()
        .map(|f| f.iter().filter(|&&p| p > 0).count())
        .sum();
    assert!(
        visible_objects >= walk.frames as usize,
        "the walk sees almost nothing"
    );
    full
}

/// (frame, object, visible pixels) of every object visible in the full render of a frame
/// that `driver` did not draw in that frame.
fn missed_objects(
    scene: &WorkloadScene,
    walk: &Walk,
    full: &[Vec<u64>],
    driver: &DriverOptions,
) -> Vec<(usize, usize, u64)> {
    let stats = generate(scene, driver, walk, &mut Discard).unwrap();
    let mut missed = Vec::new();
    for (frame, (frame_stats, visible)) in stats.frames.iter().zip(full).enumerate() {
        let mut drawn = vec![false; visible.len()];
        for &object in &frame_stats.objects_drawn {
            drawn[object as usize] = true;
        }
        for (object, &pixels) in visible.iter().enumerate() {
            if pixels > 0 && !drawn[object] {
                missed.push((frame, object, pixels));
            }
        }
    }
    missed
}

/// Every object with a visible pixel in the full render of a frame is drawn in that frame.
fn check_conservative(scene: &WorkloadScene, walk: &Walk) {
    let full = full_renders(scene, walk);
    for driver in conservative_drivers() {
        let missed = missed_objects(scene, walk, &full, &driver);
        assert!(
            missed.is_empty(),
            "{} on {}: culls visible objects (frame, object, pixels): {missed:?}",
            driver.label(),
            scene.name
        );
    }
}

#[test]
fn the_full_render_check_catches_an_adaptive_driver_losing_pixels() {
    let scene = small_city();
    let full = full_renders(&scene, &WALK);
    let mut adaptive = DriverOptions::new(DriverKind::Hierarchical);
    adaptive.adaptive_threshold = Some(0.9);
    assert!(!missed_objects(&scene, &WALK, &full, &adaptive).is_empty());
}

#[test]
fn conservative_drivers_draw_every_visible_object_in_the_city() {
    check_conservative(&small_city(), &WALK);
}

#[test]
fn conservative_drivers_draw_every_visible_object_in_the_forest() {
    check_conservative(&small_forest(), &WALK);
}

#[test]
fn conservative_drivers_draw_every_visible_object_in_moving_traffic() {
    // Long enough for hidden cars' TBVs to expire and be renewed (the first lasts 4 frames).
    let walk = Walk { frames: 12, ..WALK };
    check_conservative(&small_traffic(), &walk);
}

#[test]
fn the_dynamic_grid_follows_cars_and_culls_them_without_queries() {
    let scene = small_traffic();
    let walk = Walk { frames: 8, ..WALK };
    let full = full_renders(&scene, &walk);
    // The cars are the objects after the city's buildings and ground.
    let cars = scene.object_count() - small_city().object_count();
    let first_car = scene.object_count() - cars;
    let visible_cars: usize = full
        .iter()
        .map(|f| f[first_car..].iter().filter(|&&p| p > 0).count())
        .sum();
    assert!(
        visible_cars > 0,
        "no car is ever seen: the test shows nothing"
    );
    let walk_with = |kind| generate(&scene, &DriverOptions::new(kind), &walk, &mut Discard);
    let frustum = walk_with(DriverKind::Frustum).unwrap();
    let grid = walk_with(DriverKind::DynamicGrid).unwrap();
    // A query is asked only of the grid's potentially visible set: far fewer objects than
    // frustum culling draws, the rest culled on the grid alone.
    let in_view: u64 = frustum
        .frames
        .iter()
        .map(|f| f.objects_drawn.len() as u64)
        .sum();
    let queries: u64 = grid.frames.iter().map(|f| f.queries).sum();
    assert!(
        queries * 2 < in_view,
        "{queries} queries for {in_view} objects in view"
    );
}

#[test]
fn raycast_rays_are_saved_and_an_overflow_casts_a_superset() {
    let scene = small_city();
    let rays = |entries: u32| {
        let mut driver = DriverOptions::new(DriverKind::Raycast);
        driver.verbose_buffer_entries = entries;
        let stats = generate(&scene, &driver, &WALK, &mut Discard).unwrap();
        let cast: u64 = stats.frames.iter().map(|f| f.rays_cast).sum();
        let full: u64 = stats.frames.iter().map(|f| f.rays_full_screen).sum();
        let overflows: u64 = stats.frames.iter().map(|f| f.overflowed_buffers).sum();
        (cast, full, overflows)
    };
    // A buffer large enough for every brick's hits (160 x 120 pixels at most) never
    // overflows; one of 8 + 16 entries does, and its bricks cast through their hit boxes.
    let (exact, full, none) = rays(8 + 160 * 120);
    assert_eq!(none, 0);
    assert_eq!(full, WALK.frames as u64 * 160 * 120);
    assert!(exact > 0 && exact < full, "{exact} rays of {full}");
    let (boxed, _, overflows) = rays(8 + 16);
    assert!(overflows > 0);
    assert!(
        boxed >= exact,
        "the fallback casts {boxed}, fewer than the hits' {exact}"
    );
}

#[test]
fn conservative_drivers_draw_every_visible_object_at_odd_sizes() {
    // A viewport that is not a multiple of the cell size, looking across the blocks.
    let scene = small_city().with_camera(
        CameraPath::line(
            [-150.0, 12.0, 20.0],
            [150.0, 30.0, -80.0],
            [0.0, 0.0, -150.0],
        )
        .unwrap(),
    );
    let walk = Walk {
        frames: 3,
        width: 97,
        height: 61,
        ..WALK
    };
    check_conservative(&scene, &walk);
}

#[test]
fn occlusion_culling_draws_fewer_triangles_than_frustum_culling_in_the_city() {
    let scene = small_city();
    let triangles = |driver: &DriverOptions| -> u64 {
        let stats = generate(&scene, driver, &WALK, &mut Discard).unwrap();
        stats.frames.iter().map(|f| f.triangles_drawn).sum()
    };
    let frustum = triangles(&DriverOptions::new(DriverKind::Frustum));
    assert!(frustum > 0);
    let mut drivers: Vec<DriverOptions> = [
        DriverKind::Hierarchical,
        DriverKind::LazyGrid,
        DriverKind::BusyGrid,
        DriverKind::Hom,
        DriverKind::LargeOccluders,
    ]
    .into_iter()
    .map(DriverOptions::new)
    .collect();
    let mut occlusion_buffer = DriverOptions::new(DriverKind::LazyGrid);
    occlusion_buffer.grid_variant = GridVariant::OcclusionBuffer;
    drivers.push(occlusion_buffer);
    for driver in drivers {
        let culled = triangles(&driver);
        assert!(
            culled * 4 < frustum * 3,
            "{}: {culled} triangles against frustum culling's {frustum}",
            driver.label()
        );
    }
}

#[test]
fn the_lazy_grid_refreshes_fewer_cells_than_the_busy_grid() {
    let scene = small_city();
    let refreshed = |kind| -> u64 {
        let stats = generate(&scene, &DriverOptions::new(kind), &WALK, &mut Discard).unwrap();
        stats.frames.iter().map(|f| f.cells_refreshed).sum()
    };
    let (lazy, busy) = (
        refreshed(DriverKind::LazyGrid),
        refreshed(DriverKind::BusyGrid),
    );
    assert!(lazy < busy, "lazy {lazy} busy {busy}");
}

#[test]
fn an_adaptive_threshold_draws_no_more_than_the_conservative_traversal() {
    let scene = small_city();
    let drawn = |threshold: Option<f32>| -> u64 {
        let mut driver = DriverOptions::new(DriverKind::Hierarchical);
        driver.adaptive_threshold = threshold;
        let stats = generate(&scene, &driver, &WALK, &mut Discard).unwrap();
        stats
            .frames
            .iter()
            .map(|f| f.objects_drawn.len() as u64)
            .sum()
    };
    let exact = drawn(None);
    let adaptive = drawn(Some(0.5));
    assert!(adaptive < exact, "adaptive {adaptive} exact {exact}");
}

/// Hom: the occlusion map is read by queries whose tiles are its pixels, the host's tests
/// are charged, and approximate culling (opacity threshold below 1) draws fewer objects than
/// conservative culling and loses pixels of the full render.
#[test]
fn hom_reads_its_map_by_queries_and_approximate_culling_loses_pixels() {
    let scene = small_city();
    let full = full_renders(&scene, &WALK);
    let conservative = DriverOptions::new(DriverKind::Hom);
    let stats = generate(&scene, &conservative, &WALK, &mut Discard).unwrap();
    for frame in &stats.frames {
        // 160x120 in 4-pixel cells: 40 x 30 = 1200 map pixels, in one query (under 8,192).
        assert_eq!(frame.queries, 1);
        assert_eq!(frame.query_tiles, 1200);
        assert_eq!(
            frame.query_fragments,
            160 * 120,
            "one quad over the viewport"
        );
        // At least the map, its 20x15, 10x8, 5x4, 3x2 averages and the overlap tests.
        assert!(frame.host_tests > 1200 + 300 + 80 + 20 + 6, "{frame:?}");
    }
    // 640x480: 160 x 120 = 19,200 map pixels; a query holds at most 8,192, i.e. 51 rows of
    // 160, so the map takes bands of 51, 51 and 18 rows: 3 queries.
    let wide = Walk {
        frames: 1,
        width: 640,
        height: 480,
        ..WALK
    };
    let wide_stats = generate(&scene, &conservative, &wide, &mut Discard).unwrap();
    assert_eq!(wide_stats.frames[0].queries, 3);
    assert_eq!(wide_stats.frames[0].query_tiles, 19_200);
    let drawn = |stats: &occsim_traces::workloads::WorkloadStats| -> u64 {
        stats
            .frames
            .iter()
            .map(|f| f.objects_drawn.len() as u64)
            .sum()
    };
    let mut approximate = DriverOptions::new(DriverKind::Hom);
    approximate.opacity_threshold = 0.5;
    let loose = generate(&scene, &approximate, &WALK, &mut Discard).unwrap();
    assert!(
        drawn(&loose) < drawn(&stats),
        "{} {}",
        drawn(&loose),
        drawn(&stats)
    );
    assert!(!missed_objects(&scene, &WALK, &full, &approximate).is_empty());
}

/// Large occluders: no queries at all; from a camera that stands still, the second frame
/// draws what the first did and finds every occluder-node pair's planes in the cache, so
/// its host tests are fewer (eye tests only, no tangent planes computed).
#[test]
fn large_occluders_reuse_their_planes_between_frames() {
    let scene = small_city().with_camera(
        CameraPath::line([0.0, 1.7, 60.0], [0.0, 1.7, 60.0], [0.0, 1.7, -100.0]).unwrap(),
    );
    let walk = Walk { frames: 2, ..WALK };
    let stats = generate(
        &scene,
        &DriverOptions::new(DriverKind::LargeOccluders),
        &walk,
        &mut Discard,
    )
    .unwrap();
    let (first, second) = (&stats.frames[0], &stats.frames[1]);
    assert_eq!(first.queries + second.queries, 0);
    assert_eq!(first.objects_drawn, second.objects_drawn);
    assert!(
        second.host_tests < first.host_tests,
        "{} then {}",
        first.host_tests,
        second.host_tests
    );
}

#[test]
fn a_query_delay_draws_everything_in_view_on_the_first_frame() {
    let scene = small_city();
    let walk = Walk { frames: 3, ..WALK };
    let mut delayed = DriverOptions::new(DriverKind::Hierarchical);
    delayed.query_delay_frames = 1;
    let late = generate(&scene, &delayed, &walk, &mut Discard).unwrap();
    let frustum = generate(
        &scene,
        &DriverOptions::new(DriverKind::Frustum),
        &walk,
        &mut Discard,
    )
    .unwrap();
    assert_eq!(
        late.frames[0].objects_drawn.len(),
        frustum.frames[0].objects_drawn.len()
    );
    assert!(
        late.frames[0].queries > 0,
        "queries are issued for the next frame"
    );
    let later: u64 = late.frames[1..].iter().map(|f| f.triangles_drawn).sum();
    let baseline: u64 = frustum.frames[1..].iter().map(|f| f.triangles_drawn).sum();
    assert!(
        later < baseline,
        "delayed answers cull nothing: {later} against {baseline}"
    );
}

#[test]
fn bad_options_are_refused_clearly() {
    let scene = small_forest();
    let error = |driver: &DriverOptions, walk: &Walk| {
        generate(&scene, driver, walk, &mut Discard)
            .unwrap_err()
            .to_string()
    };
    let lazy = DriverOptions::new(DriverKind::LazyGrid);
    assert_eq!(
        error(&lazy, &Walk { frames: 0, ..WALK }),
        "frames 0 out of range: a walkthrough has 1 to 1000000 frames"
    );
    let endless = Walk {
        frames: MAX_WALK_FRAMES + 1,
        ..WALK
    };
    assert!(error(&lazy, &endless).starts_with("frames 1000001 out of range"));
    assert!(error(&lazy, &Walk { width: 0, ..WALK }).contains("width 0 out of range"));
    let mut delayed_grid = lazy.clone();
    delayed_grid.query_delay_frames = 1;
    assert!(
        error(&delayed_grid, &WALK).contains("query delay applies to the frustum and hierarchical")
    );
    let mut deep = DriverOptions::new(DriverKind::Hierarchical);
    deep.quadtree_levels = 9;
    assert!(error(&deep, &WALK).contains("quadtree levels 9 out of range"));
    let mut threshold = DriverOptions::new(DriverKind::Hierarchical);
    threshold.adaptive_threshold = Some(1.5);
    assert!(error(&threshold, &WALK).contains("adaptive threshold 1.5 out of range"));
    let mut fine_grid = lazy.clone();
    fine_grid.grid_cell_pixels = 4;
    let huge = Walk {
        width: 1280,
        height: 1024,
        ..WALK
    };
    assert!(error(&fine_grid, &huge).contains("makes a 320x256 grid, more than 65536 cells"));
    let unknown = "z-pyramid".parse::<DriverKind>().unwrap_err().to_string();
    assert_eq!(
        unknown,
        "unknown driver `z-pyramid`: expected one of frustum, hierarchical, lazy-grid, busy-grid, collision, hom, large-occluders, dynamic-grid, raycast"
    );
    let mut opaque = DriverOptions::new(DriverKind::Hom);
    opaque.opacity_threshold = 1.5;
    assert!(error(&opaque, &WALK).contains("opacity threshold 1.5 out of range"));
    let mut not_hom = DriverOptions::new(DriverKind::Hierarchical);
    not_hom.opacity_threshold = 0.5;
    assert!(error(&not_hom, &WALK).contains("opacity threshold applies to the hom driver only"));
    let mut flat_hom = DriverOptions::new(DriverKind::Hom);
    flat_hom.flat_grid = true;
    assert!(error(&flat_hom, &WALK).contains("flat grid applies to the dynamic-grid driver only"));
    let mut tiny = DriverOptions::new(DriverKind::Raycast);
    tiny.verbose_buffer_entries = 7;
    assert!(error(&tiny, &WALK).contains("verbose buffer 7 out of range"));
    let obj = load_obj(
        "v 0 0 0\nf 1 1\n".as_bytes(),
        "model.obj",
        &ObjOptions::default(),
    );
    // A face of two corners is no triangle: refused on its line (the loader had dropped it,
    // and the model, left with none, was refused for having no faces).
    assert!(obj.is_err_and(|e| e
        .to_string()
        .starts_with("model.obj:2: face `f 1 1` has 2 corners")));
    let camera = CameraPath::from_toml("[[keyframe]]\neye = [1, 2]\n", "walk.toml").unwrap_err();
    assert!(camera.to_string().starts_with("walk.toml: "), "{camera}");
}

#[test]
fn an_obj_model_walks_with_every_driver() {
    // Two unit cubes, one behind the other as seen from the camera.
    let mut text = String::new();
    for (index, z) in [0.0f32, -4.0].into_iter().enumerate() {
        let base = index * 8;
        for corner in 0..8 {
            let (x, y, dz) = (
                (corner & 1) as f32,
                ((corner >> 1) & 1) as f32,
                ((corner >> 2) & 1) as f32,
            );
            text += &format!("v {x} {y} {}\n", z + dz);
        }
        text += &format!("o cube{index}\n");
        // Faces counter-clockwise from outside (1-based corners: bit0 x, bit1 y, bit2 z).
        for face in [
            [1, 3, 4, 2],
            [5, 6, 8, 7],
            [1, 2, 6, 5],
            [3, 7, 8, 4],
            [1, 5, 7, 3],
            [2, 4, 8, 6],
        ] {
            let f = face.map(|c| c + base);
            text += &format!("f {} {} {} {}\n", f[0], f[1], f[2], f[3]);
        }
    }
    let scene = load_obj(text.as_bytes(), "cubes.obj", &ObjOptions::default())
        .unwrap()
        .with_camera(
            CameraPath::line([0.5, 0.5, 6.0], [0.6, 0.5, 5.0], [0.5, 0.5, -10.0]).unwrap(),
        );
    assert_eq!(scene.object_count(), 2);
    let walk = Walk {
        frames: 2,
        width: 64,
        height: 64,
        ..WALK
    };
    check_conservative(&scene, &walk);
    let full = full_render_visible_pixels(&scene, 0, &walk).unwrap();
    assert!(full[0] > 0 && full[1] == 0, "{full:?}");
    for kind in [DriverKind::Hierarchical, DriverKind::LazyGrid] {
        let stats = generate(&scene, &DriverOptions::new(kind), &walk, &mut Discard).unwrap();
        assert_eq!(stats.frames[0].objects_drawn, vec![0], "{}", kind.name());
    }
}

#[test]
fn the_virtual_occlusion_buffer_draws_what_the_occlusion_unit_does_and_reads_the_boxes_back() {
    let scene = small_city();
    let walk = Walk {
        frames: 2,
        width: 160,
        height: 120,
        raster: RasterProfile::default(),
    };
    let hierarchical = DriverOptions::new(DriverKind::Hierarchical);
    let mut vob = hierarchical.clone();
    vob.virtual_occlusion_buffer = true;
    assert_eq!(vob.label(), "hierarchical/vob");
    let run = |options: &DriverOptions| {
        let mut events: Vec<Event> = Vec::new();
        let stats = generate(&scene, options, &walk, &mut events).unwrap();
        (stats, events)
    };
    let ((unit_stats, unit_events), (vob_stats, vob_events)) = (run(&hierarchical), run(&vob));
    // The same decisions: the same objects drawn, frame by frame.
    let drawn = |stats: &occsim_traces::workloads::WorkloadStats| -> Vec<Vec<u32>> {
        stats
            .frames
            .iter()
            .map(|f| f.objects_drawn.clone())
            .collect()
    };
    assert_eq!(drawn(&unit_stats), drawn(&vob_stats));
    let pixels = |events: &[Event]| -> u64 {
        events
            .iter()
            .map(|e| match e {
                Event::HostWork(w) => w.pixels as u64,
                _ => 0,
            })
            .sum()
    };
    assert_eq!(
        pixels(&unit_events),
        0,
        "the Occlusion Unit's record is read, not pixels"
    );
    // Every box test reads its rectangle: at least one pixel per query, at most the screen.
    let queries: u64 = vob_stats.frames.iter().map(|f| f.queries).sum();
    let read = pixels(&vob_events);
    assert!(queries > 0);
    assert!(
        read >= queries && read <= queries * 160 * 120,
        "{read} pixels for {queries} queries"
    );
    // One wait per query, and one frame end per frame, in both.
    for events in [&unit_events, &vob_events] {
        let waits = events
            .iter()
            .filter(|e| matches!(e, Event::Wait(_)))
            .count() as u64;
        let swaps = events.iter().filter(|e| matches!(e, Event::Swap)).count();
        assert_eq!((waits, swaps), (queries, 2));
    }
}

#[test]
fn a_query_delay_never_waits_and_an_immediate_answer_always_does() {
    let scene = small_city();
    let walk = Walk {
        frames: 3,
        width: 160,
        height: 120,
        raster: RasterProfile::default(),
    };
    for kind in [DriverKind::Frustum, DriverKind::Hierarchical] {
        for delay in [0, 1] {
            let mut options = DriverOptions::new(kind);
            options.query_delay_frames = delay;
            let mut events: Vec<Event> = Vec::new();
            let stats = generate(&scene, &options, &walk, &mut events).unwrap();
            let queries: u64 = stats.frames.iter().map(|f| f.queries).sum();
            let waits = events
                .iter()
                .filter(|e| matches!(e, Event::Wait(_)))
                .count() as u64;
            let expected = if delay == 0 { queries } else { 0 };
            assert_eq!(waits, expected, "{} with delay {delay}", options.label());
        }
    }
}

#[test]
fn collision_tests_agree_with_the_geometric_oracle() {
    // Every tile's answer lies between the oracle's bounds: a tile a front-facing triangle
    // surely covers nearer than the far plane collides; a tile no triangle possibly reaches
    // nearer than it does not. Steps of 5 and 60 metres and the walk's own steps give both
    // answers along the city walk.
    let scene = small_city();
    let walk = Walk { frames: 8, ..WALK };
    let (mut collided, mut free, mut untested) = (0, 0, 0);
    for step in [None, Some(5.0), Some(60.0)] {
        let mut options = DriverOptions::new(DriverKind::Collision);
        options.collision_step = step;
        let stats = generate(&scene, &options, &walk, &mut Discard).unwrap();
        for (frame, frame_stats) in stats.frames.iter().enumerate() {
            let Some(test) = &frame_stats.collision else {
                untested += 1;
                continue;
            };
            assert_eq!(test.tiles.len(), 4, "2 x 2 tiles by default");
            for &(tile, hit) in &test.tiles {
                let (surely, possibly) =
                    collision_oracle(&scene, frame as u32, &walk, tile, test.step);
                let context = format!("step {step:?} frame {frame} tile {tile:?}");
                assert!(
                    !surely || hit,
                    "{context}: surely collides, the query says free"
                );
                assert!(
                    !hit || possibly,
                    "{context}: nothing there, the query says collides"
                );
                if hit {
                    collided += 1;
                } else {
                    free += 1;
                }
            }
        }
    }
    assert!(collided > 0 && free > 0, "collided {collided}, free {free}");
    assert!(untested < 3 * walk.frames as usize, "every frame untested");
}

/// Takes each frame's statistics as the frame ends and keeps none in the walk's.
struct Streamed(Vec<occsim_traces::workloads::FrameStats>);

impl occsim_traces::workloads::CommandObserver for Streamed {
    fn command(&mut self, _: &occsim_traces::Command) {}

    fn frame(&mut self, stats: &occsim_traces::workloads::FrameStats) -> bool {
        self.0.push(stats.clone());
        false
    }
}

#[test]
fn an_observer_that_streams_the_frames_leaves_none_kept() {
    // `trace gen` streams each frame's lines as it ends: a walk of any length then keeps
    // no frame (its 160,000 frames at 16x16 had kept 27 MB and taken 59 s, a line printed
    // a frame scanning every frame before it). The frames it sees are the ones kept
    // otherwise, in order.
    let scene = small_city();
    let driver = DriverOptions::new(DriverKind::Hierarchical);
    let kept = generate(&scene, &driver, &WALK, &mut Discard).unwrap();
    let mut streamed = Streamed(Vec::new());
    let stats = occsim_traces::workloads::generate_observed(
        &scene,
        &driver,
        &WALK,
        &mut Discard,
        &mut streamed,
    )
    .unwrap();
    assert!(stats.frames.is_empty() && stats.timing.is_empty());
    assert_eq!(streamed.0.len(), WALK.frames as usize);
    assert_eq!(streamed.0, kept.frames);
}
