//! `MapFile::to_text` writes a map that parses back to an equal map.

use flockstep_world::{parse_map, Scenario};

use crate::common::TINY;

#[test]
fn the_thesis_maps_round_trip() {
    for name in ["s1", "s2", "s3"] {
        let map = Scenario::builtin(name).expect("builtin").map().clone();
        let text = map.to_text();
        let again = parse_map("again.map", &text).expect("the written map parses");
        assert_eq!(again, map);
        assert_eq!(again.to_text(), text, "writing is stable");
    }
}

#[test]
fn lists_none_and_two_digit_labels_round_trip() {
    let map = parse_map("tiny.map", TINY).expect("tiny");
    let again = parse_map("again.map", &map.to_text()).expect("reparse");
    assert_eq!(again, map);
    assert_eq!(again.expects[2].poses, vec![]);
    assert_eq!(again.expects[0].poses.len(), 4);

    // Twelve targets in a row: the writer pads `.` and `X` to the width of `T10`.
    let row: Vec<String> = (1..=12).map(|k| format!("T{k}")).collect();
    let text = format!(
        "name: wide one\nsize: 3 12\nstart: 1 high E\ngrid:\n{}\n.  X  {}\n{}\n\
         route UAV1: 2,0 2,11\n",
        row.join(" "),
        ["."; 10].join(" "),
        ["."; 12].join(" ")
    );
    let map = parse_map("wide.map", &text).expect("wide");
    let written = map.to_text();
    assert!(written.contains("\n.   X   .   "), "{written}");
    assert!(written.contains("start: wp1 high E\n"), "{written}");
    assert_eq!(parse_map("again.map", &written).expect("reparse"), map);
}

#[test]
fn facts_are_equal_whatever_their_order_and_line() {
    let shuffled = TINY.replace(
        "expect UAV1 T1: 1 low N, 1 high N, 2 high E, 3 high E",
        "# moved\n\nexpect UAV1 T1: wp3 high E, 2 high E, 1 high N, 1 low N",
    );
    let a = parse_map("a.map", TINY).expect("a");
    let b = parse_map("b.map", &shuffled).expect("b");
    assert_ne!(a.expects[1].line, b.expects[1].line);
    assert_eq!(a, b);
}

#[test]
fn a_map_made_in_memory_loads_through_its_text() {
    let mut map = parse_map("tiny.map", TINY).expect("tiny");
    map.name = "generated".to_string();
    map.expects.pop();
    let scenario = Scenario::from_text("generated.map", &map.to_text()).expect("loads");
    assert_eq!(scenario.map(), &map);
    assert_eq!(scenario.source_text(), map.to_text());
    // A fact that does not hold is refused with a line of the written text.
    map.expects[0].poses.pop();
    let message =
        Scenario::from_text("generated.map", &map.to_text()).expect_err("refused").to_string();
    assert!(message.starts_with("generated.map:"), "{message}");
    assert!(message.contains("does not hold"), "{message}");
}
