//! Hard cases for every rasterizer profile. Expected values come from hand reasoning, from
//! the independent oracle below (exact rational point-in-triangle on vertices snapped by its
//! own integer arithmetic), or from Mesa llvmpipe itself (counts measured with Mesa 22.3,
//! named where used), never from the rasterizer.

use occsim_traces::event::DEPTH_ONE;
use occsim_traces::golden::{infallible, Discard, GoldenModel};
use occsim_traces::raster::{rasterize_triangle, RasterProfile, RasterSink};
use occsim_traces::state::RenderState;
use occsim_traces::{Command, DepthFunc, Fragment, QuerySpec, Rect};
use proptest::prelude::*;

/// Records what the rasterizer emits.
#[derive(Default)]
struct Recorder {
    primitives: usize,
    fragments: Vec<Fragment>,
}

impl RasterSink for Recorder {
    fn primitive(&mut self) {
        self.primitives += 1;
    }
    fn fragment(&mut self, fragment: Fragment) {
        self.fragments.push(fragment);
    }
}

/// The exact profile, whose depths the oracle predicts.
fn raster(state: &RenderState, tri: &[[f32; 4]; 3]) -> Recorder {
    raster_with(RasterProfile::Exact, state, tri)
}

fn raster_with(profile: RasterProfile, state: &RenderState, tri: &[[f32; 4]; 3]) -> Recorder {
    let mut recorder = Recorder::default();
    rasterize_triangle(profile, state, tri, &mut recorder);
    recorder
}

/// Clip coordinate of a window coordinate along a side (exact for power-of-two sides and
/// window coordinates on a 1/512 grid).
fn clip(window: f64, side: u32) -> f32 {
    let half = side as f64 / 2.0;
    ((window - half) / half) as f32
}

/// A triangle from window (x, y) and window depth z, w = 1.
fn window_tri(state: &RenderState, v: [(f64, f64, f64); 3]) -> [[f32; 4]; 3] {
    v.map(|(x, y, z)| {
        [
            clip(x, state.width),
            clip(y, state.height),
            (2.0 * z - 1.0) as f32,
            1.0,
        ]
    })
}

// ----------------------------------------------------------------------------------------
// The oracle: vertices given as window coordinates in 1/512 pixel units and window depth in
// 1/1024 units, snapped and quantised by integer arithmetic; coverage and depth from exact
// barycentric coordinates.

/// Round n/2 to the nearest integer, ties to even.
fn half_to_even(n: i64) -> i64 {
    let floor = n.div_euclid(2);
    if n.rem_euclid(2) == 0 || floor % 2 == 0 {
        floor
    } else {
        floor + 1
    }
}

#[derive(Clone, Debug)]
struct OracleVertex {
    /// Window coordinate · 512.
    x512: i64,
    y512: i64,
    /// Window depth · 1024.
    z1024: i64,
}

impl OracleVertex {
    /// Snapped offset coordinates: (window - 1/2) · 256 = (x512 - 256) / 2, ties to even.
    fn snapped(&self) -> (i128, i128) {
        (
            half_to_even(self.x512 - 256) as i128,
            half_to_even(self.y512 - 256) as i128,
        )
    }

    /// round(z · (2^24 - 1) · 256) = round(z1024 · (2^24 - 1) / 4), ties up.
    fn depth_fixed(&self) -> i128 {
        (self.z1024 as i128 * DEPTH_ONE as i128 + 2).div_euclid(4)
    }
}

fn cross(o: (i128, i128), a: (i128, i128), b: (i128, i128)) -> i128 {
    (a.0 - o.0) * (b.1 - o.1) - (a.1 - o.1) * (b.0 - o.0)
}

/// Fragments of the triangle by brute force over every pixel of the bounds, rows bottom to
/// top, left to right. The tie rule stated as in the module doc, in terms of the edge's
/// inward normal: a centre on an edge is covered when that normal points right (+x), or
/// straight up (+y) for a horizontal edge.
fn oracle(state: &RenderState, v: &[OracleVertex; 3]) -> (usize, Vec<Fragment>) {
    let p: Vec<(i128, i128)> = v.iter().map(OracleVertex::snapped).collect();
    let area = cross(p[0], p[1], p[2]);
    if area == 0 || (state.cull_back && area < 0) {
        return (0, Vec::new());
    }
    let bounds = state.raster_bounds();
    let mut fragments = Vec::new();
    for py in bounds.y..bounds.y + bounds.height {
        for px in bounds.x..bounds.x + bounds.width {
            let centre = (256 * px as i128, 256 * py as i128);
            let mut weights = [0i128; 3];
            let mut inside = true;
            for k in 0..3 {
                let (a, b, opposite) = (p[(k + 1) % 3], p[(k + 2) % 3], p[k]);
                // Weight of vertex k: signed area of (a, b, centre), sign-normalised.
                let s = cross(a, b, centre) * area.signum();
                weights[k] = s;
                if s < 0 {
                    inside = false;
                } else if s == 0 {
                    // Inward normal of edge a-b: perpendicular, towards the opposite vertex.
                    let (mut nx, mut ny) = (-(b.1 - a.1), b.0 - a.0);
                    let towards = nx * (opposite.0 - a.0) + ny * (opposite.1 - a.1);
                    if towards < 0 {
                        nx = -nx;
                        ny = -ny;
                    }
                    if !(nx > 0 || (nx == 0 && ny > 0)) {
                        inside = false;
                    }
                }
            }
            if inside {
                let d = area.abs();
                let numerator: i128 = (0..3).map(|k| weights[k] * v[k].depth_fixed()).sum();
                // round(numerator / (d · 256)), ties up.
                let z = (2 * numerator + 256 * d).div_euclid(512 * d);
                fragments.push(Fragment {
                    x: px as u16,
                    y: py as u16,
                    z: z.clamp(0, DEPTH_ONE as i128) as u32,
                });
            }
        }
    }
    (1, fragments)
}

fn oracle_clip(state: &RenderState, v: &[OracleVertex; 3]) -> [[f32; 4]; 3] {
    let c = |n: i64, side: u32| clip(n as f64 / 512.0, side);
    [0, 1, 2].map(|k| {
        [
            c(v[k].x512, state.width),
            c(v[k].y512, state.height),
            (v[k].z1024 as f64 / 512.0 - 1.0) as f32,
            1.0,
        ]
    })
}

fn vertex_strategy(width: u32, height: u32) -> impl Strategy<Value = OracleVertex> {
    let (w, h) = (width as i64 * 512, height as i64 * 512);
    (-w / 2..w * 3 / 2, -h / 2..h * 3 / 2, 0i64..=1024)
        .prop_map(|(x512, y512, z1024)| OracleVertex { x512, y512, z1024 })
}

/// Small coordinates (a few pixels) make slivers, needles and exact hits common.
fn small_vertex_strategy() -> impl Strategy<Value = OracleVertex> {
    (
        0i64..8 * 512,
        0i64..8 * 512,
        prop::sample::select(vec![0i64, 1, 512, 1023, 1024]),
    )
        .prop_map(|(x512, y512, z1024)| OracleVertex {
            x512: x512 & !0x7f | (x512 & 1),
            y512: y512 & !0x7f | (y512 & 1),
            z1024,
        })
}

fn state_strategy() -> impl Strategy<Value = RenderState> {
    (
        any::<bool>(),
        prop::option::of((0u32..64, 0u32..32, 0u32..64, 0u32..32)),
    )
        .prop_map(|(cull_back, scissor)| {
            let mut state = RenderState::new(64, 32);
            state.cull_back = cull_back;
            state.scissor = scissor.map(|(x, y, w, h)| Rect::new(x, y, w, h));
            state
        })
}

/// How many times each pixel is covered by a mesh over the `columns` x `rows` grid of
/// `point(i, j)`: cell (i, j) split along one diagonal or the other as `diagonals[i·7 + j]`
/// says, triangle k's winding flipped when `flips[k mod 98]`.
fn mesh_coverage(
    profile: RasterProfile,
    state: &RenderState,
    (columns, rows): (usize, usize),
    point: impl Fn(usize, usize) -> [f32; 4],
    diagonals: &[bool],
    flips: &[bool],
) -> Vec<u32> {
    let mut counts = vec![0u32; (state.width * state.height) as usize];
    let mut triangle = 0;
    for i in 0..columns {
        for j in 0..rows {
            let (p00, p10) = (point(i, j), point(i + 1, j));
            let (p11, p01) = (point(i + 1, j + 1), point(i, j + 1));
            let halves = if diagonals[i * 7 + j] {
                [[p00, p10, p11], [p00, p11, p01]]
            } else {
                [[p00, p10, p01], [p10, p11, p01]]
            };
            for mut tri in halves {
                if flips[triangle % 98] {
                    tri.swap(1, 2);
                }
                triangle += 1;
                for f in raster_with(profile, state, &tri).fragments {
                    counts[f.y as usize * state.width as usize + f.x as usize] += 1;
                }
            }
        }
    }
    counts
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn rasterizer_agrees_with_the_oracle(
        state in state_strategy(),
        a in vertex_strategy(64, 32),
        b in vertex_strategy(64, 32),
        c in vertex_strategy(64, 32),
    ) {
        let v = [a, b, c];
        let (primitives, expected) = oracle(&state, &v);
        let got = raster(&state, &oracle_clip(&state, &v));
        prop_assert_eq!(got.primitives, primitives);
        prop_assert_eq!(got.fragments, expected);
    }

    #[test]
    fn rasterizer_agrees_with_the_oracle_on_slivers_and_ties(
        a in small_vertex_strategy(),
        b in small_vertex_strategy(),
        c in small_vertex_strategy(),
    ) {
        let state = RenderState::new(8, 8);
        let v = [a, b, c];
        let (primitives, expected) = oracle(&state, &v);
        let got = raster(&state, &oracle_clip(&state, &v));
        prop_assert_eq!(got.primitives, primitives);
        prop_assert_eq!(got.fragments, expected);
    }

    /// A jittered grid, each cell split along a random diagonal, vertex order random:
    /// every pixel is covered exactly once.
    #[test]
    fn jittered_meshes_are_watertight(
        columns in 1usize..7,
        rows in 1usize..7,
        jitter in prop::collection::vec((-0.24f32..0.24, -0.24f32..0.24), 64),
        diagonals in prop::collection::vec(any::<bool>(), 49),
        flips in prop::collection::vec(any::<bool>(), 98),
        w in prop::sample::select(vec![1.0f32, 0.7, 3.0]),
    ) {
        let state = RenderState::new(48, 40);
        let point = |i: usize, j: usize| -> [f32; 4] {
            let (jx, jy) = jitter[(i * 8 + j) % 64];
            let fx = if i == 0 || i == columns { 0.0 } else { jx };
            let fy = if j == 0 || j == rows { 0.0 } else { jy };
            let x = -1.0 + 2.0 * (i as f32 + fx) / columns as f32;
            let y = -1.0 + 2.0 * (j as f32 + fy) / rows as f32;
            [x * w, y * w, 0.0, w]
        };
        let counts = mesh_coverage(RasterProfile::Exact, &state, (columns, rows), point, &diagonals, &flips);
        let wrong: Vec<(usize, u32)> = counts.iter().copied().enumerate().filter(|&(_, c)| c != 1).collect();
        prop_assert!(wrong.is_empty(), "pixels not covered exactly once (index, count): {:?}", wrong);
    }
}

#[test]
fn square_split_on_a_diagonal_through_centres() {
    // Square [0.5, 4.5]^2: its left and bottom edges and its diagonal pass through centres.
    // Owned: left and bottom, so columns and rows 0..=3 (16 pixels). The lower-right half has
    // the diagonal as a left edge (interior to its right): it owns x >= y, 4+3+2+1 = 10.
    let state = RenderState::new(8, 8);
    for profile in RasterProfile::ALL {
        let lower = raster_with(
            profile,
            &state,
            &window_tri(&state, [(0.5, 0.5, 0.0), (4.5, 0.5, 0.0), (4.5, 4.5, 0.0)]),
        );
        let upper = raster_with(
            profile,
            &state,
            &window_tri(&state, [(0.5, 0.5, 0.0), (4.5, 4.5, 0.0), (0.5, 4.5, 0.0)]),
        );
        assert_eq!(lower.fragments.len(), 10, "{profile}");
        assert_eq!(upper.fragments.len(), 6);
        assert!(lower.fragments.iter().all(|f| f.x >= f.y && f.x <= 3));
        assert!(upper.fragments.iter().all(|f| f.x < f.y && f.y <= 3));
        // Bottom to top, left to right.
        let order: Vec<(u16, u16)> = lower.fragments.iter().map(|f| (f.y, f.x)).collect();
        let mut sorted = order.clone();
        sorted.sort();
        assert_eq!(order, sorted);
    }
}

#[test]
fn zero_area_triangles_produce_nothing() {
    let state = RenderState::new(8, 8);
    for tri in [
        [(1.0, 1.0, 0.5), (3.0, 3.0, 0.5), (6.0, 6.0, 0.5)], // collinear
        [(2.0, 2.0, 0.5), (2.0, 2.0, 0.5), (5.0, 1.0, 0.5)], // repeated vertex
        [
            (1.0, 1.0, 0.5),
            (1.0 + 1.0 / 1024.0, 7.0, 0.5),
            (1.0, 1.0 + 1.0 / 1024.0, 0.5),
        ], // snaps flat
    ] {
        for profile in RasterProfile::ALL {
            let got = raster_with(profile, &state, &window_tri(&state, tri));
            assert_eq!(
                (got.primitives, got.fragments.len()),
                (0, 0),
                "{profile} {tri:?}"
            );
        }
    }
}

#[test]
fn back_faces_are_culled_only_when_asked() {
    let mut state = RenderState::new(8, 8);
    let clockwise = window_tri(&state, [(0.0, 0.0, 0.5), (0.0, 8.0, 0.5), (8.0, 0.0, 0.5)]);
    // Centres (px + 1/2, py + 1/2) with px + py < 7 are strictly inside: 7+6+...+1 = 28.
    // Those with px + py = 7 lie on the hypotenuse, a right/top edge: not owned.
    let expected = 28;
    for profile in RasterProfile::ALL {
        state.cull_back = false;
        assert_eq!(
            raster_with(profile, &state, &clockwise).fragments.len(),
            expected
        );
        state.cull_back = true;
        let got = raster_with(profile, &state, &clockwise);
        assert_eq!((got.primitives, got.fragments.len()), (0, 0), "{profile}");
    }
}

#[test]
fn huge_triangles_far_outside_cover_the_viewport_exactly() {
    // What llvmpipe covers of each: it clips to the viewport in f32 and leaves each new
    // vertex where its interpolation rounds, up to pixels inside the edge for coordinates of
    // 10^6 and more. Measured with Mesa 22.3.6 llvmpipe into an FBO, one triangle a query.
    let llvmpipe = [
        ((64, 48), [2976, 1152, 3008]),
        ((16384, 1), [15872, 0, 16288]),
        ((1, 16384), [16384, 8192, 16192]),
    ];
    for ((width, height), mesa) in llvmpipe {
        let state = RenderState::new(width, height);
        for (k, tri) in [
            [
                [-1e6f32, -1e6, 0.0, 1.0],
                [3e6, -1e6, 0.0, 1.0],
                [-1e6, 3e6, 0.0, 1.0],
            ],
            [
                [-3e30f32, -3e30, 0.0, 1.0],
                [3e30, -3e30, 0.0, 1.0],
                [0.0, 3e30, 0.0, 1.0],
            ],
            [
                [-1e4f32, -1e4, 0.0, 1e-3],
                [1e4, -1e4, 0.0, 1e-3],
                [0.0, 1e4, 0.0, 1e-3],
            ],
        ]
        .iter()
        .enumerate()
        {
            for profile in RasterProfile::ALL {
                let got = raster_with(profile, &state, tri);
                let pixels = width as u64 * height as u64;
                let mut seen = vec![false; pixels as usize];
                for f in &got.fragments {
                    let slot = &mut seen[f.y as usize * width as usize + f.x as usize];
                    assert!(!*slot, "{profile}: pixel drawn twice");
                    *slot = true;
                }
                let count = got.fragments.len() as u64;
                match profile {
                    // The guard band keeps such vertices exact enough to cover every pixel.
                    RasterProfile::Exact => assert_eq!(count, pixels, "{width}x{height} {tri:?}"),
                    RasterProfile::Llvmpipe => {
                        assert_eq!(count, mesa[k], "{width}x{height} {tri:?}")
                    }
                    // Mirrored, the same clipped vertices land on other rows' rounding:
                    // tests/mesa_diff.rs compares it with a pbuffer.
                    RasterProfile::LlvmpipeWindow => assert!(count <= pixels),
                }
                // z = 0 in clip space: window depth 1/2; (2^24 - 1) / 2 = 2^23 - 1/2 rounds to
                // 2^23 both by the exact profile's ties-up and llvmpipe's ties-to-even.
                assert!(got.fragments.iter().all(|f| f.z == 1 << 23), "{profile}");
            }
        }
    }
}

#[test]
fn near_and_far_planes_clip_and_nothing_comes_from_behind_the_eye() {
    let state = RenderState::new(64, 32);
    // Entirely behind the eye, or beyond near or far: nothing.
    for tri in [
        [
            [-1.0f32, -1.0, 0.0, -1.0],
            [1.0, -1.0, 0.0, -1.0],
            [0.0, 1.0, 0.0, -1.0],
        ],
        [
            [-1.0, -1.0, -1.5, 1.0],
            [1.0, -1.0, -1.5, 1.0],
            [0.0, 1.0, -1.5, 1.0],
        ],
        [
            [-1.0, -1.0, 1.5, 1.0],
            [1.0, -1.0, 1.5, 1.0],
            [0.0, 1.0, 1.5, 1.0],
        ],
    ] {
        for profile in RasterProfile::ALL {
            let got = raster_with(profile, &state, &tri);
            assert_eq!(
                (got.primitives, got.fragments.len()),
                (0, 0),
                "{profile} {tri:?}"
            );
        }
    }
    // A full-screen quad whose z runs from -4 to 4 across x: only -1 <= z <= 1 survives,
    // x in [-1/4, 1/4], window columns 24..40: 16 · 32 pixels. Depth rises left to right
    // from about 0 to about 1.
    let quad = [
        [
            [-1.0f32, -1.0, -4.0, 1.0],
            [1.0, -1.0, 4.0, 1.0],
            [1.0, 1.0, 4.0, 1.0],
        ],
        [
            [-1.0f32, -1.0, -4.0, 1.0],
            [1.0, 1.0, 4.0, 1.0],
            [-1.0, 1.0, -4.0, 1.0],
        ],
    ];
    let mut counts = vec![0u32; 64 * 32];
    for tri in &quad {
        for f in raster(&state, tri).fragments {
            assert!((24..40).contains(&f.x), "{f:?}");
            counts[f.y as usize * 64 + f.x as usize] += 1;
            let expected = ((f.x as f64 + 0.5) / 64.0 * 2.0 - 1.0) * 4.0 * 0.5 + 0.5;
            let z = f.z as f64 / DEPTH_ONE as f64;
            assert!(
                (z - expected).abs() < 1e-5,
                "{f:?} expected depth {expected}"
            );
        }
    }
    assert_eq!(counts.iter().filter(|&&c| c == 1).count(), 16 * 32);
    assert!(counts.iter().all(|&c| c <= 1));

    // One vertex behind the eye: the visible part is drawn, only from in front of the eye.
    let tri = [
        [-1.0f32, -1.0, 0.0, 1.0],
        [1.0, -1.0, 0.0, 1.0],
        [0.0, 4.0, -4.0, -2.0],
    ];
    let got = raster(&state, &tri);
    assert_eq!(
        got.primitives, 2,
        "clipped to a quad, fanned into two triangles"
    );
    assert!(!got.fragments.is_empty());
    // The near plane (z + w = 0) cuts A-C and B-C at t = 1/7 from A and B, at window
    // (-16, 8) and (80, 8): the bottom row (y centre 0.5, above A-B at y = 0) is full.
    assert_eq!(got.fragments.iter().filter(|f| f.y == 0).count(), 64);
}

#[test]
fn shared_edges_crossing_the_near_plane_stay_disjoint() {
    let state = RenderState::new(64, 32);
    let a = [-1.0f32, -1.0, -3.0, 1.0];
    let b = [1.0f32, -0.7, 0.5, 1.0];
    let c = [0.9f32, 1.0, 0.3, 1.0];
    let d = [-0.8f32, 0.9, -2.5, 1.0];
    for profile in RasterProfile::ALL {
        let mut counts = vec![0u32; 64 * 32];
        for tri in [[a, b, c], [a, c, d]] {
            for f in raster_with(profile, &state, &tri).fragments {
                counts[f.y as usize * 64 + f.x as usize] += 1;
            }
        }
        assert!(
            counts.iter().all(|&c| c <= 1),
            "{profile}: a pixel drawn twice"
        );
        assert!(counts.contains(&1), "{profile}");
    }
}

#[test]
fn depths_exactly_zero_and_one() {
    let state = RenderState::new(8, 8);
    for (profile, (z, expected)) in RasterProfile::ALL
        .into_iter()
        .flat_map(|p| [(p, (0.0, 0)), (p, (1.0, DEPTH_ONE))])
    {
        // The vertex (0.5, 0.5) sits on pixel (0, 0)'s centre (a bottom-left corner: owned).
        let got = raster_with(
            profile,
            &state,
            &window_tri(&state, [(0.5, 0.5, z), (8.0, 0.5, z), (0.5, 8.0, z)]),
        );
        assert_eq!(
            got.fragments[0],
            Fragment {
                x: 0,
                y: 0,
                z: expected
            },
            "{profile}"
        );
        assert!(got.fragments.iter().all(|f| f.z == expected), "{profile}");
    }
    // A slope from depth 0 to 1: the vertex pixels get exactly 0 and 2^24 - 1.
    let got = raster(
        &state,
        &window_tri(&state, [(0.5, 0.5, 0.0), (7.5, 0.5, 1.0), (0.5, 7.5, 0.0)]),
    );
    let at = |x, y| {
        got.fragments
            .iter()
            .find(|f| f.x == x && f.y == y)
            .map(|f| f.z)
    };
    assert_eq!(at(0, 0), Some(0));
    // Pixel (3, 0): centre 3.5 is 3/7 of the way: round(3/7 · (2^24 - 1)).
    assert_eq!(at(3, 0), Some(((3 * DEPTH_ONE as u64 * 2 + 7) / 14) as u32));
}

fn run_queries(model: &mut GoldenModel, commands: &[Command]) -> Vec<u64> {
    commands
        .iter()
        .filter_map(|c| infallible(model.execute(c, &mut Discard)))
        .map(|r| r.value())
        .collect()
}

#[test]
fn the_same_geometry_twice_passes_lequal_and_equal_and_fails_less() {
    let (width, height) = (64, 32);
    let spec = |id| {
        Command::Begin(QuerySpec {
            id,
            mode: occsim_traces::QueryMode::Samples,
            buffer_entries: 8,
            tiles: vec![Rect::new(0, 0, width, height)],
        })
    };
    let mut rng = occsim_traces::rng::SplitMix64(12345);
    let mut random = move || rng.below(2001) as f32 / 1000.0 - 1.0;
    let triangles: Vec<Command> = (0..20)
        .map(|_| {
            let mut v = [[0.0f32; 4]; 3];
            for vertex in &mut v {
                let w = 0.5 + (random() + 1.0);
                *vertex = [random() * w, random() * w, random() * w, w];
            }
            Command::Tri(v)
        })
        .collect();
    let mut model = GoldenModel::new(width, height);
    let mut commands = vec![Command::DepthFunc(DepthFunc::Always), spec(0)];
    commands.extend(triangles.iter().cloned());
    commands.push(Command::End);
    let first = run_queries(&mut model, &commands)[0];
    assert!(first > 0);
    // Each triangle drawn again alone against the buffer the whole set left: per pixel the
    // last writer's depth is what the buffer holds, so redraw in the same order, one query
    // per function, writes off.
    for (func, expect_all) in [
        (DepthFunc::Lequal, true),
        (DepthFunc::Equal, true),
        (DepthFunc::Less, false),
    ] {
        let mut model = GoldenModel::new(width, height);
        let mut commands = vec![Command::DepthFunc(DepthFunc::Always)];
        for t in &triangles {
            commands.push(t.clone());
            commands.push(Command::DepthMask(false));
            commands.push(Command::DepthFunc(func));
            commands.push(spec(1));
            commands.push(t.clone());
            commands.push(Command::End);
            commands.push(spec(2));
            commands.push(Command::DepthFunc(DepthFunc::Always));
            commands.push(t.clone());
            commands.push(Command::End);
            commands.push(Command::DepthMask(true));
        }
        let values = run_queries(&mut model, &commands);
        for pair in values.chunks(2) {
            let (tested, all) = (pair[0], pair[1]);
            assert_eq!(tested, if expect_all { all } else { 0 }, "{func:?}");
        }
    }
}

fn profile_strategy() -> impl Strategy<Value = RasterProfile> {
    prop::sample::select(RasterProfile::ALL.to_vec())
}

/// Vertices inside the viewport: llvmpipe clips nothing, so its coverage is the oracle's.
fn inside_vertex_strategy(width: u32, height: u32) -> impl Strategy<Value = OracleVertex> {
    (0..=width as i64 * 512, 0..=height as i64 * 512, 0i64..=1024)
        .prop_map(|(x512, y512, z1024)| OracleVertex { x512, y512, z1024 })
}

fn positions(fragments: &[Fragment]) -> Vec<(u16, u16)> {
    fragments.iter().map(|f| (f.x, f.y)).collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    /// The llvmpipe profiles snap as the oracle does (ties to even, in either framebuffer's
    /// orientation) and cover by the same rule; their depths are llvmpipe's f32 plane, so
    /// only positions and order are compared.
    #[test]
    fn llvmpipe_coverage_agrees_with_the_oracle(
        state in state_strategy(),
        profile in prop::sample::select(vec![RasterProfile::Llvmpipe, RasterProfile::LlvmpipeWindow]),
        a in inside_vertex_strategy(64, 32),
        b in inside_vertex_strategy(64, 32),
        c in inside_vertex_strategy(64, 32),
    ) {
        let v = [a, b, c];
        let (primitives, expected) = oracle(&state, &v);
        let got = raster_with(profile, &state, &oracle_clip(&state, &v));
        prop_assert_eq!(got.primitives, primitives);
        prop_assert_eq!(positions(&got.fragments), positions(&expected));
        prop_assert!(got.fragments.iter().all(|f| f.z <= DEPTH_ONE));
    }

    /// A planar mesh over a jittered grid reaching past the viewport's edges, with a random w
    /// per vertex and a depth slope that the near (and often the far) plane cuts: where a
    /// pixel centre is clearly in front of near and behind far it is covered exactly once,
    /// and nowhere twice, in every profile.
    #[test]
    fn meshes_across_the_viewport_edges_and_the_near_plane_are_watertight(
        profile in profile_strategy(),
        columns in 1usize..7,
        rows in 1usize..7,
        reach in 1.0f32..1.8,
        jitter in prop::collection::vec((-0.24f32..0.24, -0.24f32..0.24), 64),
        ws in prop::collection::vec(0.5f32..3.0, 64),
        diagonals in prop::collection::vec(any::<bool>(), 49),
        flips in prop::collection::vec(any::<bool>(), 98),
        slope in (-0.8f32..0.8, -0.8f32..0.8, -0.9f32..0.3),
    ) {
        let (width, height) = (48u32, 40u32);
        let state = RenderState::new(width, height);
        let (a, b, c) = slope;
        // z/w = a·x/w + b·y/w + c: the mesh is a plane in clip space; near is z/w = -1.
        let point = |i: usize, j: usize| -> [f32; 4] {
            let (jx, jy) = jitter[(i * 8 + j) % 64];
            let jx = if i == 0 || i == columns { 0.0 } else { jx };
            let jy = if j == 0 || j == rows { 0.0 } else { jy };
            let nx = reach * (-1.0 + 2.0 * (i as f32 + jx) / columns as f32);
            let ny = reach * (-1.0 + 2.0 * (j as f32 + jy) / rows as f32);
            let w = ws[(i * 8 + j) % 64];
            [nx * w, ny * w, (a * nx + b * ny + c) * w, w]
        };
        let counts = mesh_coverage(profile, &state, (columns, rows), point, &diagonals, &flips);
        let margin = 0.02;
        for py in 0..height {
            for px in 0..width {
                let count = counts[(py * width + px) as usize];
                prop_assert!(count <= 1, "pixel ({px}, {py}) drawn {count} times");
                let (cx, cy) = (
                    (px as f32 + 0.5) / width as f32 * 2.0 - 1.0,
                    (py as f32 + 0.5) / height as f32 * 2.0 - 1.0,
                );
                // The grid's outer vertices are not jittered and lie on or beyond the
                // viewport's edges (reach >= 1): every centre is inside its projection.
                let depth = a * cx + b * cy + c;
                if depth > -1.0 + margin && depth < 1.0 - margin {
                    prop_assert_eq!(count, 1, "{}: pixel ({}, {}) at depth {} not covered", profile, px, py, depth);
                }
            }
        }
    }

    /// Denormal inputs act as zeros (llvmpipe reads them so, DAZ; in the exact profile they
    /// vanish in the first rounding).
    #[test]
    fn denormal_coordinates_act_as_zeros(
        profile in profile_strategy(),
        which in prop::collection::vec(any::<bool>(), 12),
        bits in prop::collection::vec(1u32..0x7f_ffff, 12),
    ) {
        let state = RenderState::new(16, 16);
        let base = [[-0.9f32, -0.8, 0.0, 1.0], [0.7, -0.9, 0.0, 1.0], [0.0, 0.0, 0.0, 1.0]];
        let mut noisy = base;
        let mut k = 0;
        for vertex in &mut noisy {
            for coordinate in vertex.iter_mut().take(3) {
                if which[k] && *coordinate == 0.0 {
                    let tiny = f32::from_bits(bits[k]);
                    *coordinate = if k % 2 == 0 { tiny } else { -tiny };
                }
                k += 1;
            }
        }
        let expected = raster_with(profile, &state, &base);
        let got = raster_with(profile, &state, &noisy);
        prop_assert_eq!(got.primitives, expected.primitives);
        prop_assert_eq!(got.fragments, expected.fragments);
    }
}

/// Counts of the samples queries of `scene` under `profile`.
fn samples_counts(profile: RasterProfile, scene: &str) -> Vec<u64> {
    let lines = occsim_traces::scene::parse_scene(scene, "test").expect("a valid scene");
    let Some(Command::Viewport { width, height }) = lines.first().map(|l| l.command.clone()) else {
        panic!("no viewport");
    };
    let mut model = GoldenModel::with_profile(width, height, profile);
    let commands: Vec<Command> = lines.into_iter().map(|l| l.command).collect();
    run_queries(&mut model, &commands)
}

#[test]
fn the_issue_reproducers_count_what_llvmpipe_counts() {
    // Measured with Mesa 22.3.6 llvmpipe (FBO) and quoted in issue 11: a triangle crossing
    // the right edge, which llvmpipe clips (58; the guard band's exact profile gives 57).
    let edge = "viewport 200 150\nclear\nbegin 0\n\
        tri 1.195604 0.4832446 0.5 1  0.8642694 0.4082995 0.5 1  0.7934409 0.3295854 0.5 1\nend\n";
    assert_eq!(samples_counts(RasterProfile::Llvmpipe, edge), vec![58]);
    assert_eq!(samples_counts(RasterProfile::Exact, edge), vec![57]);
    // Two interpenetrating triangles whose f32 depth plane orders one pixel differently from
    // the exact one (llvmpipe 656 then 285; exact 656 then 284).
    let depth = "viewport 64 64\nclear\nbegin 0\n\
        tri 0.1763297 0.7665053 -0.09756832 1  -0.3205084 -0.7066074 -0.3674104 1  0.7707483 -0.0533057 -0.1754436 1\nend\n\
        begin 1\n\
        tri -0.8223223 0.3768852 -0.3658611 1  -0.001898742 0.4581878 0.3025198 1  0.6457618 -0.4365953 -0.343951 1\nend\n";
    assert_eq!(
        samples_counts(RasterProfile::Llvmpipe, depth),
        vec![656, 285]
    );
    assert_eq!(samples_counts(RasterProfile::Exact, depth), vec![656, 284]);
}

#[test]
fn a_draw_of_three_triangles_ending_flat_in_y_takes_llvmpipes_rectangle_path() {
    // Window coordinates on an 8x8 viewport (clip = window / 4 - 1). T1 (1,1) (6,1) (1,6) and
    // T2 (6,1) (6,6) (1,6) cover the 5x5 centres 1.5..5.5 (T1 owns its left and bottom
    // edges, T2 the diagonal: 15 + 10 = 25). T3 (0,7) (4,7) (7,7) is flat in y.
    let t1 = "tri -0.75 -0.75 0 1  0.5 -0.75 0 1  -0.75 0.5 0 1\n";
    let t2 = "tri 0.5 -0.75 0 1  0.5 0.5 0 1  -0.75 0.5 0 1\n";
    let flat = "tri -1 0.75 0 1  0 0.75 0 1  0.75 0.75 0 1\n";
    let query = |tris: &str| format!("viewport 8 8\nbegin 0\n{tris}end\n");
    for profile in RasterProfile::ALL {
        assert_eq!(
            samples_counts(profile, &query(&format!("{t1}{t2}"))),
            vec![25]
        );
        // Three triangles, the last flat: llvmpipe's nine-vertex path finds no rectangle in
        // T1 T2's vertex order and draws nothing at all.
        let nine = samples_counts(profile, &query(&format!("{t1}{t2}{flat}")));
        let expected = if profile == RasterProfile::Exact {
            25
        } else {
            0
        };
        assert_eq!(nine, vec![expected], "{profile}");
        // A fourth triangle makes it an ordinary draw again.
        assert_eq!(
            samples_counts(profile, &query(&format!("{t1}{t2}{flat}{flat}"))),
            vec![25]
        );
        // Split into two draws by a state command, neither has nine vertices.
        let split = format!("viewport 8 8\nbegin 0\n{t1}depth_func less\n{t2}{flat}end\n");
        assert_eq!(samples_counts(profile, &split), vec![25], "{profile}");
    }
    // In the rectangle's own order, (X0,Y0) (X0,Y1) (X1,Y1) and (X1,Y0) (X1,Y1) (X0,Y0) with
    // X0 = 5, X1 = 1, Y0 = 2, Y1 = 6, the path draws the rectangle if its snapped corners are
    // not "clockwise": (x2 < x1) ^ (y0 < y2), with x1 = X0, x2 = X1, y0 = Y0, y2 = Y1 in the
    // framebuffer's own y. In an FBO (y up): (1 < 5) ^ (2 < 6) = false, drawn: its box is
    // columns ((128 + 255) >> 8) = 1 ..= ((1152 + 255) >> 8) - 1 = 4 and rows 2 ..= 5: 16
    // pixels. In a window (y mirrored: Y0 = 6, Y1 = 2) (1 < 5) ^ (6 < 2) = true: nothing.
    let c = |x: f32, y: f32| format!("{} {} 0 1", x / 4.0 - 1.0, y / 4.0 - 1.0);
    let rect = format!(
        "tri {}  {}  {}\ntri {}  {}  {}\n{flat}",
        c(5.0, 2.0),
        c(5.0, 6.0),
        c(1.0, 6.0),
        c(1.0, 2.0),
        c(1.0, 6.0),
        c(5.0, 2.0)
    );
    assert_eq!(
        samples_counts(RasterProfile::Llvmpipe, &query(&rect)),
        vec![16]
    );
    assert_eq!(
        samples_counts(RasterProfile::LlvmpipeWindow, &query(&rect)),
        vec![0]
    );
}
