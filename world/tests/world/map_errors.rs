//! Refused maps. Each case breaks one thing in an otherwise valid map and checks that
//! the message points at it (`file:line:col`) and says what was expected.

use flockstep_world::{parse_map, MapErrorKind, Scenario};
use proptest::prelude::*;

use crate::common::{assert_refused, with_line, without_line, TINY};

#[test]
fn the_small_map_is_valid() {
    let scenario = Scenario::from_text("tiny.map", TINY).expect("tiny.map loads");
    assert_eq!((scenario.n_routes(), scenario.n_targets()), (2, 2));
}

#[test]
fn a_broken_fact_shows_the_poses_that_do_see_the_target() {
    assert_refused(
        &with_line(14, "expect UAV1 T2: 2 high E, 4 low N"),
        "tiny.map:14: ",
        &[
            "fact `expect UAV1 T2: 2 high E, 4 low N` does not hold",
            "UAV1 sees T2 from wp2 high E, wp3 high E, wp4 low N",
        ],
    );
}

#[test]
fn a_fact_about_a_target_never_seen_says_so() {
    assert_refused(
        &with_line(15, "expect UAV2 T1: 1 high E"),
        "tiny.map:15: ",
        &["`expect UAV2 T1: 1 high E` does not hold", "UAV2 sees T1 from no pose"],
    );
}

#[test]
fn a_broken_thesis_fact_is_refused_with_the_truth() {
    let text = include_str!("../../maps/s2_one_uav_two_targets.map");
    let line = text.lines().position(|l| l.starts_with("expect UAV1 T1")).expect("fact") + 1;
    let broken = text.replace("expect UAV1 T1: 6 high E", "expect UAV1 T1: 6 low E");
    let message = Scenario::from_text("s2.map", &broken).expect_err("refused").to_string();
    assert!(message.starts_with(&format!("s2.map:{line}: ")), "{message}");
    assert!(message.contains("UAV1 sees T1 from wp6 high E"), "{message}");
}

#[test]
fn a_waypoint_on_an_occlusion_is_refused() {
    assert_refused(
        &with_line(11, "route UAV1: 4,3 1,1 0,0 3,5"),
        "tiny.map:11:17: ",
        &["waypoint 1,1 is on an `X` cell", "expected a free cell"],
    );
}

#[test]
fn a_waypoint_off_the_grid_is_refused() {
    assert_refused(
        &with_line(12, "route UAV2: 4,0 4,6"),
        "tiny.map:12:17: ",
        &["waypoint 4,6 is off the 5x6 grid", "expected row < 5 and col < 6"],
    );
}

#[test]
fn a_malformed_waypoint_is_refused() {
    assert_refused(
        &with_line(12, "route UAV2: 4;0"),
        "tiny.map:12:13: ",
        &["expected a waypoint `row,col`", "found `4;0`"],
    );
}

#[test]
fn a_ragged_row_is_refused() {
    assert_refused(
        &with_line(7, ".  X  .  T1 ."),
        "tiny.map:7:14: ",
        &["this grid row has 5 cells, expected 6"],
    );
    assert_refused(
        &with_line(7, ".  X  .  T1 .  .  ."),
        "tiny.map:7:19: ",
        &["this grid row has 7 cells, expected 6"],
    );
}

#[test]
fn a_wrong_number_of_rows_is_refused() {
    assert_refused(&without_line(10), "tiny.map:5:1: ", &["the grid has 4 rows, expected 5"]);
    let extra = with_line(10, ".  .  .  .  .  .\n.  .  .  .  .  .");
    assert_refused(&extra, "tiny.map:11:1: ", &["the grid has 6 rows, expected 5"]);
}

#[test]
fn a_duplicate_header_is_refused() {
    assert_refused(
        &with_line(1, "name: again"),
        "tiny.map:2:1: ",
        &["duplicate `name:` line (first given at line 1)"],
    );
}

#[test]
fn a_missing_header_is_refused() {
    assert_refused(
        &without_line(3),
        "tiny.map:15:1: ",
        &["missing `size:` line", "`size: <rows> <cols>`"],
    );
    assert_refused("", "tiny.map:1:1: ", &["missing `name:` line"]);
}

#[test]
fn a_malformed_size_is_refused() {
    assert_refused(
        &with_line(3, "size: 5 zero"),
        "tiny.map:3:9: ",
        &["expected the number of columns (an integer >= 1), found `zero`"],
    );
}

#[test]
fn an_unknown_cell_is_refused() {
    assert_refused(
        &with_line(8, ".  .  .  .  Y  T2"),
        "tiny.map:8:13: ",
        &["unknown cell `Y`", "`X` (occlusion)"],
    );
    assert_refused(
        &with_line(7, ".  X  .  T0 .  ."),
        "tiny.map:7:10: ",
        &["unknown cell `T0`", "k >= 1"],
    );
}

#[test]
fn target_labels_must_be_unique_and_contiguous() {
    assert_refused(
        &with_line(8, ".  .  .  .  X  T1"),
        "tiny.map:8:16: ",
        &["duplicate target `T1` (first at line 7, column 10)"],
    );
    assert_refused(
        &with_line(8, ".  .  .  .  X  T3"),
        "tiny.map:8:16: ",
        &["labelled T1..T3 without gaps", "`T2` is missing"],
    );
    assert_refused(
        &with_line(8, ".  .  .  .  X  T65"),
        "tiny.map:8:16: ",
        &["too many targets", "at most 64"],
    );
}

#[test]
fn a_target_no_route_sees_is_refused() {
    // From 0,0 the corner target is two ahead and two aside (too wide) in every heading.
    let text = "name: hidden\nsize: 3 3\nstart: wp1 low N\ngrid:\n\
                .  .  .\n.  X  .\n.  .  T1\nroute UAV1: 0,0\n";
    assert_refused(
        text,
        "tiny.map:7:7: ",
        &["target T1 at 2,2 is visible from no pose of any route"],
    );
}

#[test]
fn routes_are_named_in_order_and_not_empty() {
    assert_refused(
        &with_line(12, "route UAV3: 4,0 4,5"),
        "tiny.map:12:7: ",
        &["expected route name `UAV2`", "found `UAV3`"],
    );
    assert_refused(
        &with_line(12, "route UAV2:"),
        "tiny.map:12:7: ",
        &["route UAV2 has no waypoints"],
    );
}

#[test]
fn route_and_target_limits_are_enforced() {
    let long = format!("route UAV1: {}", vec!["4,3"; 1025].join(" "));
    assert_refused(
        &with_line(11, &long),
        &format!("tiny.map:11:{}: ", 13 + 1024 * 4),
        &["too many waypoints: 1025, at most 1024"],
    );
    let routes: Vec<String> = (1..=65).map(|k| format!("route UAV{k}: 4,3")).collect();
    let text = format!(
        "{}\n{}\n",
        TINY.lines().take(10).collect::<Vec<_>>().join("\n"),
        routes.join("\n")
    );
    assert_refused(&text, "tiny.map:75:1: ", &["too many routes: 65, at most 64"]);
}

#[test]
fn the_start_waypoint_must_be_on_every_route() {
    assert_refused(
        &with_line(4, "start: wp3 low N"),
        "tiny.map:4:8: ",
        &["start waypoint wp3 is beyond UAV2's route of 2 waypoints"],
    );
}

#[test]
fn an_expect_must_name_a_known_uav_and_target() {
    assert_refused(
        &with_line(15, "expect UAV3 T1: none"),
        "tiny.map:15:8: ",
        &["unknown UAV `UAV3`", "UAV1..UAV2"],
    );
    assert_refused(
        &with_line(15, "expect UAV2 T3: none"),
        "tiny.map:15:13: ",
        &["unknown target `T3`", "T1..T2"],
    );
    assert_refused(
        &with_line(16, "expect UAV2 T1: none"),
        "tiny.map:16:8: ",
        &["duplicate fact for UAV2 T1 (first at line 15)"],
    );
}

#[test]
fn a_malformed_pose_is_refused() {
    assert_refused(
        &with_line(16, "expect UAV2 T2: 1 high E, 2 middle N"),
        "tiny.map:16:29: ",
        &["expected a height `low` or `high`, found `middle`"],
    );
    assert_refused(
        &with_line(16, "expect UAV2 T2: 1 high, 2 low N"),
        "tiny.map:16:23: ",
        &["expected a heading `N`, `E`, `S` or `W`, found `,`"],
    );
    assert_refused(
        &with_line(16, "expect UAV2 T2: 0 high E"),
        "tiny.map:16:17: ",
        &["expected a waypoint number >= 1", "found `0`"],
    );
    assert_refused(
        &with_line(16, "expect UAV2 T2: 1 high E 2 low N"),
        "tiny.map:16:26: ",
        &["expected `,` or end of line after the pose, found `2`"],
    );
    assert_refused(
        &with_line(16, "expect UAV2 T2: 1 high E, 3 low N"),
        "tiny.map:16:27: ",
        &["pose wp3 is beyond UAV2's route of 2 waypoints"],
    );
    assert_refused(
        &with_line(16, "expect UAV2 T2: 1 high E, 1 high E"),
        "tiny.map:16:27: ",
        &["pose wp1 high E is listed twice"],
    );
}

#[test]
fn an_unknown_or_malformed_line_is_refused() {
    assert_refused(
        &with_line(1, "speed: 5"),
        "tiny.map:1:1: ",
        &["unexpected `speed:`", "expected `name:`"],
    );
    assert_refused(
        &with_line(11, "route UAV1 4,3 2,0"),
        "tiny.map:11:12: ",
        &["expected `:` as in `route UAV<k>: <row>,<col> ...`", "found `4,3`"],
    );
    assert_refused(
        &with_line(5, "grid: 5"),
        "tiny.map:5:7: ",
        &["expected end of line after `grid:`", "found `5`"],
    );
}

#[test]
fn errors_carry_their_position_and_kind() {
    let err = parse_map("tiny.map", &with_line(8, ".  .  .  .  Y  T2")).expect_err("refused");
    assert_eq!((err.file.as_str(), err.line, err.col), ("tiny.map", 8, 13));
    assert_eq!(err.kind, MapErrorKind::UnknownCell { token: "Y".to_string() });
}

#[test]
fn a_missing_file_is_an_unknown_scenario_that_names_its_path() {
    let message = Scenario::resolve("no/such/file.map").expect_err("refused").to_string();
    assert!(
        message.starts_with("unknown scenario `no/such/file.map`: expected s1, s2, s3, s4, "),
        "{message}"
    );
    assert!(message.ends_with("there is no file `no/such/file.map`"), "{message}");
    // A file that exists but cannot be read is named as such.
    let message = Scenario::resolve("/").expect_err("a directory").to_string();
    assert!(message.starts_with("cannot read /: "), "{message}");
}

proptest! {
    /// Refused or not, never a panic; a refusal points into the text (or just past its
    /// end, for what is missing): 1-based, at most one column past the line's end.
    #[test]
    fn any_text_is_parsed_or_refused_without_panic(text in "\\PC{0,300}") {
        if let Err(err) = parse_map("any.map", &text) {
            prop_assert_eq!(err.file.as_str(), "any.map");
            let lines: Vec<&str> = text.lines().collect();
            prop_assert!((1..=lines.len() + 1).contains(&err.line), "{:?}", err);
            let width = lines.get(err.line - 1).map_or(0, |line| line.chars().count());
            prop_assert!((1..=width + 1).contains(&err.col), "{:?}", err);
        }
    }

    #[test]
    fn a_mangled_line_is_loaded_or_refused_without_panic(
        line in 1usize..=16,
        junk in "[ .XT0-9UAVwplowhighNESnoe,:#-]{0,40}",
    ) {
        if let Ok(scenario) = Scenario::from_text("tiny.map", &with_line(line, &junk)) {
            for uav in 0..scenario.n_routes() {
                let _ = flockstep_world::optimum::optimum(&scenario, uav);
            }
        }
    }
}
