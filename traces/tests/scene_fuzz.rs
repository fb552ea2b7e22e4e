//! Random and mutated bytes into the scene parser: always a clean error or success.

use occsim_traces::builtin::HARDCASES;
use occsim_traces::scene::{SceneError, SceneReader};
use proptest::prelude::*;

/// Parse bytes; on error, check the message names the file and a line that exists.
fn parse_cleanly(bytes: &[u8]) {
    let line_count = bytes.split(|&b| b == b'\n').count() as u32;
    for item in SceneReader::new(bytes, "fuzz.scene") {
        match item {
            Ok(_) => {}
            Err(SceneError::Syntax {
                file,
                line,
                message,
            }) => {
                assert_eq!(file, "fuzz.scene");
                assert!(line <= line_count, "line {line} of {line_count}: {message}");
                assert!(!message.is_empty());
                return;
            }
            // No command at all (the first line mutated into a comment or blanks): the
            // file, no line.
            Err(SceneError::Empty { file }) => {
                assert_eq!(file, "fuzz.scene");
                return;
            }
            Err(other) => panic!("unexpected error kind: {other}"),
        }
    }
}

#[derive(Debug, Clone)]
enum Mutation {
    Flip(usize, u8),
    Insert(usize, u8),
    Delete(usize),
}

fn mutate(text: &[u8], mutations: &[Mutation]) -> Vec<u8> {
    let mut bytes = text.to_vec();
    for m in mutations {
        let len = bytes.len().max(1);
        match *m {
            Mutation::Flip(at, bits) => {
                if let Some(b) = bytes.get_mut(at % len) {
                    *b ^= bits;
                }
            }
            Mutation::Insert(at, byte) => bytes.insert(at % (bytes.len() + 1), byte),
            Mutation::Delete(at) => {
                if !bytes.is_empty() {
                    bytes.remove(at % len);
                }
            }
        }
    }
    bytes
}

fn mutation() -> impl Strategy<Value = Mutation> {
    let interesting = prop_oneof![
        any::<u8>(),
        Just(b'\n'),
        Just(b'#'),
        Just(b' '),
        Just(b'-'),
        Just(b'e'),
        Just(b'9'),
        Just(b'='),
        Just(b','),
    ];
    prop_oneof![
        (any::<usize>(), 1u8..=255).prop_map(|(a, b)| Mutation::Flip(a, b)),
        (any::<usize>(), interesting).prop_map(|(a, b)| Mutation::Insert(a, b)),
        any::<usize>().prop_map(Mutation::Delete),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
        parse_cleanly(&bytes);
    }

    #[test]
    fn random_command_soup_never_panics(words in proptest::collection::vec(
        prop_oneof![
            Just("viewport"), Just("begin"), Just("end"), Just("tri"), Just("scissor"),
            Just("off"), Just("brief"), Just("verbose"), Just("buffer=8"), Just("tile=0,0,1,1"),
            Just("1"), Just("0"), Just("-1"), Just("4294967296"), Just("nan"), Just("1e38"),
            Just("\n"), Just("depth_func"), Just("less"), Just("clear"),
        ], 0..80)) {
        parse_cleanly(words.join(" ").as_bytes());
    }

    #[test]
    fn mutated_scenes_never_panic(mutations in proptest::collection::vec(mutation(), 1..8)) {
        parse_cleanly(&mutate(HARDCASES.as_bytes(), &mutations));
    }
}

#[test]
fn the_unmutated_catalogue_parses() {
    let lines: Result<Vec<_>, _> = SceneReader::new(HARDCASES.as_bytes(), "hardcases").collect();
    assert!(lines.unwrap().len() > 100);
}

#[test]
fn an_overlong_line_is_an_error_not_an_allocation() {
    let mut text = b"viewport 4 4\n# ".to_vec();
    text.extend(std::iter::repeat_n(b'x', (1 << 20) + 10));
    let error = SceneReader::new(&text[..], "long.scene")
        .find_map(Result::err)
        .expect("an error");
    assert!(
        error
            .to_string()
            .starts_with("long.scene:2: line longer than"),
        "{error}"
    );
}
