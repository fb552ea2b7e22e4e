//! Golden digests: the built-in scenes and their fragment streams must be the same bit for
//! bit in every build (debug or release) and on every platform. A change that alters them
//! on purpose regenerates the digests with `OCCSIM_BLESS=1 cargo test --test golden_digests
//! -- --nocapture` and says why in its commit.
//!
//! (A debug and a release build once made different demo scenes: `f32::tan` of a constant was
//! folded by the compiler in one and computed by the platform's libm in the other.)
//!
//! Every rasterizer profile has its own fragment digest. The `exact` profile's are those
//! pinned before profiles existed (it is the rasterizer occsim had then, unchanged). The
//! demo's scene text is made with the default profile's answers.

use occsim_traces::builtin::{demo_scene, random_scene, DemoOptions, RandomOptions};
use occsim_traces::golden::{EventSink, GoldenModel};
use occsim_traces::raster::RasterProfile;
use occsim_traces::rng::Fnv1a;
use occsim_traces::scene::{parse_scene, Command};
use occsim_traces::Event;

/// Fragments into the one digest (FNV-1a).
struct Fnv(Fnv1a);

impl Fnv {
    fn new() -> Fnv {
        Fnv(Fnv1a::default())
    }

    fn bytes(&mut self, bytes: &[u8]) {
        self.0.bytes(bytes);
    }
}

impl EventSink for Fnv {
    type Error = std::convert::Infallible;
    fn event(&mut self, event: &Event) -> Result<(), Self::Error> {
        if let Event::Fragment(f) = event {
            self.bytes(&f.x.to_le_bytes());
            self.bytes(&f.y.to_le_bytes());
            self.bytes(&f.z.to_le_bytes());
        }
        Ok(())
    }
}

/// (digest of the scene text, digest of its fragments under `profile`).
fn digests(text: &str, profile: RasterProfile) -> (u64, u64) {
    let mut scene = Fnv::new();
    scene.bytes(text.as_bytes());
    let lines = parse_scene(text, "scene").expect("parses");
    let Command::Viewport { width, height } = lines[0].command else {
        panic!("no viewport")
    };
    let mut golden = GoldenModel::with_profile(width, height, profile);
    let mut fragments = Fnv::new();
    for line in &lines {
        golden.execute(&line.command, &mut fragments).unwrap();
    }
    golden.finish(&mut fragments);
    (scene.0 .0, fragments.0 .0)
}

/// `expected`: the scene text's digest, then the fragments' under each profile in
/// `RasterProfile::ALL` order.
fn check(name: &str, text: &str, expected: (u64, [u64; 3])) {
    for (profile, fragments) in RasterProfile::ALL.into_iter().zip(expected.1) {
        let actual = digests(text, profile);
        if std::env::var_os("OCCSIM_BLESS").is_some() {
            println!(
                "{name} {profile}: (0x{:016x}, 0x{:016x})",
                actual.0, actual.1
            );
            continue;
        }
        assert_eq!(
            (format!("{:016x}", actual.0), format!("{:016x}", actual.1)),
            (format!("{:016x}", expected.0), format!("{fragments:016x}")),
            "{name}, {profile}: (scene text, fragments) digests changed"
        );
    }
}

#[test]
fn small_demo_is_the_same_everywhere() {
    let options = DemoOptions {
        width: 320,
        height: 256,
        frames: 2,
        ..DemoOptions::default()
    };
    // The scene text's digest changed on purpose when the demo learnt to `wait` for each
    // occlusion test's answer and to `swap` at each frame's end; the fragments did not.
    check(
        "demo 320x256",
        &demo_scene(&options),
        (
            0x0324545c188fb5ec,
            [0x8a777b24f5460335, 0x05cf6a946dd8d4bc, 0xee47b11edc8c92de],
        ),
    );
}

#[test]
fn small_random_scene_is_the_same_everywhere() {
    let options = RandomOptions {
        width: 320,
        height: 256,
        triangles: 500,
        queries: 50,
        ..RandomOptions::default()
    };
    check(
        "random 320x256",
        &random_scene(&options),
        (
            0x4c3e5e0f1d6a2fef,
            [0x13cce6afcfeab7a2, 0x6f71be8215300757, 0xba8430bc7eb404ed],
        ),
    );
}
