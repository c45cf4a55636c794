//! A small map whose facts were worked out by hand, and helpers to break it.

use flockstep_world::Scenario;

/// Line numbers matter: error tests point at them. T1 is behind the `X` at 1,1 from the
/// west, T2 behind the `X` at 2,4 from the west; UAV2 never sees T1.
pub const TINY: &str = "\
# a small map for the tests
name: tiny
size: 5 6
start: wp1 low N
grid:
.  .  .  .  .  .
.  X  .  T1 .  .
.  .  .  .  X  T2
.  .  .  .  .  .
.  .  .  .  .  .
route UAV1: 4,3 2,0 0,0 3,5
route UAV2: 4,0 4,5
expect UAV1 T1: 1 low N, 1 high N, 2 high E, 3 high E
expect UAV1 T2: 2 high E, 3 high E, 4 low N
expect UAV2 T1: none
expect UAV2 T2: 1 high E, 2 low N
";

/// `TINY` with line `line` (1-based) replaced by `new`.
pub fn with_line(line: usize, new: &str) -> String {
    TINY.lines()
        .enumerate()
        .map(|(i, l)| if i + 1 == line { new } else { l })
        .collect::<Vec<_>>()
        .join("\n")
}

/// `TINY` without line `line` (1-based).
pub fn without_line(line: usize) -> String {
    TINY.lines()
        .enumerate()
        .filter(|&(i, _)| i + 1 != line)
        .map(|(_, l)| l)
        .collect::<Vec<_>>()
        .join("\n")
}

/// The message refusing `text` (read as `tiny.map`); panics if it loads.
pub fn refusal(text: &str) -> String {
    match Scenario::from_text("tiny.map", text) {
        Ok(_) => panic!("the map was accepted:\n{text}"),
        Err(e) => e.to_string(),
    }
}

/// Asserts that `text` is refused with a message starting with `prefix` and containing
/// every one of `words`.
pub fn assert_refused(text: &str, prefix: &str, words: &[&str]) {
    let message = refusal(text);
    assert!(message.starts_with(prefix), "expected prefix `{prefix}`, got: {message}");
    for word in words {
        assert!(message.contains(word), "expected `{word}` in: {message}");
    }
}
