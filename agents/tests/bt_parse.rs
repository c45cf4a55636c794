//! The behavior-tree text format end to end: thesis Fig. 5 and every extension kind parse,
//! draw and round-trip, and every malformed case of SPEC 1.1 is refused with its location
//! (`source:line:col:`) and a message saying what was expected.

use flockstep_agents::bt::parse::{parse_tree, ParseError, MAX_DEPTH, MAX_NODES};
use flockstep_agents::bt::render::{render_ascii, to_text};
use flockstep_agents::bt::spec::{LeafCatalog, LeafKind, NodeKind, NodeSpec, TreeSpec};

/// The product's catalog of UAV leaves (thesis 3.3).
use flockstep_agents::uav::UavCatalog as Uav;

const FIG5: &str = "\
OR 2
- AND 2
-- C-seeTarget 0
-- A-endEpisode 0
- LOR 5
-- A-rotate 0
-- A-elevate 0
-- A-rotate 0
-- A-deElevate 0
-- A-waypointTranslation 0
";

/// Every kind beyond the thesis's, with its parameters.
const EXTENDED: &str = "\
OR* 3
- AND* 2
-- NOT 1
--- C-seeTarget 0
-- FORCE_SUCCESS 1
--- A-rotate 0
- PAR 3 m=2
-- REPEAT 1 n=3
--- A-elevate 0
-- RETRY 1 n=1000
--- A-deElevate 0
-- FORCE_FAILURE 1
--- A-waypointTranslation 0
- PAR 2 m=2
-- LOR 1
--- A-endEpisode 0
-- A-rotate 0
";

fn parse(text: &str) -> Result<TreeSpec, ParseError> {
    parse_tree("t.bt", text, &Uav)
}

fn parse_ok(text: &str) -> TreeSpec {
    parse(text).unwrap_or_else(|error| panic!("{error}"))
}

/// The message of a text that must be refused.
fn error(text: &str) -> String {
    match parse(text) {
        Ok(tree) => panic!("accepted:\n{}", render_ascii(&tree)),
        Err(error) => error.to_string(),
    }
}

/// Asserts that `text` is refused at `location` (`line:col`) with a message containing
/// every one of `words`.
fn assert_refused(text: &str, location: &str, words: &[&str]) {
    let message = error(text);
    let prefix = format!("t.bt:{location}: ");
    assert!(message.starts_with(&prefix), "expected {prefix:?}, got {message:?}");
    for word in words {
        assert!(message.contains(word), "expected {word:?} in {message:?}");
    }
}

/// A multi-line literal written from its second line, so the first keeps its leading spaces.
fn block(text: &str) -> &str {
    text.strip_prefix('\n').unwrap_or(text)
}

fn node(kind: NodeKind, line: usize, children: Vec<NodeSpec>) -> NodeSpec {
    NodeSpec { kind, children, line }
}

fn action(name: &str, line: usize) -> NodeSpec {
    let leaf = Uav.resolve(LeafKind::Action, name).expect("a UAV action");
    node(NodeKind::Action { leaf, name: name.to_owned() }, line, vec![])
}

fn condition(name: &str, line: usize) -> NodeSpec {
    let leaf = Uav.resolve(LeafKind::Condition, name).expect("a UAV condition");
    node(NodeKind::Condition { leaf, name: name.to_owned() }, line, vec![])
}

/// A shape without its source lines, for comparing trees read from different texts.
fn without_lines(mut node: NodeSpec) -> NodeSpec {
    node.line = 0;
    node.children = node.children.into_iter().map(without_lines).collect();
    node
}

#[test]
fn fig5_parses_to_the_thesis_tree() {
    let expected = node(
        NodeKind::Fallback { memory: false },
        1,
        vec![
            node(
                NodeKind::Sequence { memory: false },
                2,
                vec![condition("seeTarget", 3), action("endEpisode", 4)],
            ),
            node(
                NodeKind::Learning,
                5,
                vec![
                    action("rotate", 6),
                    action("elevate", 7),
                    action("rotate", 8),
                    action("deElevate", 9),
                    action("waypointTranslation", 10),
                ],
            ),
        ],
    );
    assert_eq!(parse_ok(FIG5), TreeSpec { source: "t.bt".into(), root: expected });
}

#[test]
fn fig5_renders_as_ascii() {
    let expected = block(
        r"
 1  OR
 2  ├── AND
 3  │   ├── C-seeTarget
 4  │   └── A-endEpisode
 5  └── LOR
 6      ├── A-rotate
 7      ├── A-elevate
 8      ├── A-rotate
 9      ├── A-deElevate
10      └── A-waypointTranslation
",
    );
    assert_eq!(render_ascii(&parse_ok(FIG5)), expected);
}

#[test]
fn fig5_is_its_own_canonical_text() {
    let tree = parse_ok(FIG5);
    assert_eq!(to_text(&tree), FIG5);
    assert_eq!(parse_ok(&to_text(&tree)), tree);
}

#[test]
fn every_extension_kind_round_trips() {
    let tree = parse_ok(EXTENDED);
    assert_eq!(to_text(&tree), EXTENDED);
    assert_eq!(parse_ok(&to_text(&tree)), tree);
}

#[test]
fn extension_kinds_render_with_their_parameters() {
    let expected = block(
        r"
 1  OR*
 2  ├── AND*
 3  │   ├── NOT
 4  │   │   └── C-seeTarget
 5  │   └── FORCE_SUCCESS
 6  │       └── A-rotate
 7  ├── PAR m=2
 8  │   ├── REPEAT n=3
 9  │   │   └── A-elevate
10  │   ├── RETRY n=1000
11  │   │   └── A-deElevate
12  │   └── FORCE_FAILURE
13  │       └── A-waypointTranslation
14  └── PAR m=2
15      ├── LOR
16      │   └── A-endEpisode
17      └── A-rotate
",
    );
    assert_eq!(render_ascii(&parse_ok(EXTENDED)), expected);
}

#[test]
fn extension_kinds_parse_to_their_node_kinds() {
    let root = parse_ok(EXTENDED).root;
    let kinds: Vec<&NodeKind> = root.children.iter().map(|child| &child.kind).collect();
    assert_eq!(root.kind, NodeKind::Fallback { memory: true });
    assert_eq!(
        kinds,
        [
            &NodeKind::Sequence { memory: true },
            &NodeKind::Parallel { success_threshold: 2 },
            &NodeKind::Parallel { success_threshold: 2 },
        ]
    );
    let par = &root.children[1];
    let decorators: Vec<&NodeKind> = par.children.iter().map(|child| &child.kind).collect();
    assert_eq!(
        decorators,
        [
            &NodeKind::Repeat { times: 3 },
            &NodeKind::Retry { attempts: 1000 },
            &NodeKind::ForceFailure
        ]
    );
    assert_eq!(root.children[0].children[0].kind, NodeKind::Inverter);
    assert_eq!(root.children[0].children[1].kind, NodeKind::ForceSuccess);
}

#[test]
fn par_without_m_needs_all_children() {
    let tree = parse_ok("PAR 2\n- A-rotate 0\n- A-elevate 0\n");
    assert_eq!(tree.root.kind, NodeKind::Parallel { success_threshold: 2 });
    assert_eq!(to_text(&tree), "PAR 2 m=2\n- A-rotate 0\n- A-elevate 0\n");
}

#[test]
fn comments_blank_lines_crlf_and_extra_spaces_are_tolerated() {
    let text = "\u{feff}# Fig. 5 of the thesis\r\n\
                OR 2   # root\r\n\
                \r\n\
                -  AND\t2 \r\n\
                -- C-seeTarget 0\t\r\n\
                -- A-endEpisode 0\r\n\
                \x20   # indented comment\r\n\
                - LOR 5\r\n\
                -- A-rotate 0\r\n\
                --\tA-elevate 0\r\n\
                -- A-rotate    0\r\n\
                -- A-deElevate 0 #\r\n\
                -- A-waypointTranslation 0";
    let tree = parse_ok(text);
    assert_eq!(tree.root.line, 2);
    assert_eq!(tree.root.children[1].line, 8);
    assert_eq!(without_lines(tree.root), without_lines(parse_ok(FIG5).root));
}

#[test]
fn parse_error_fields_match_its_display() {
    let error = parse("OR 1\n- A-fly 0\n").expect_err("unknown leaf");
    assert_eq!((error.file.as_str(), error.line, error.col), ("t.bt", 2, 3));
    assert_eq!(
        error.to_string(),
        "t.bt:2:3: unknown action `fly`; expected one of \
         rotate, elevate, deElevate, waypointTranslation, endEpisode"
    );
}

#[test]
fn empty_file_is_refused() {
    assert_refused("", "1:1", &["empty tree", "expected a root node"]);
}

#[test]
fn file_of_comments_and_blank_lines_is_refused_as_empty() {
    assert_refused("# nothing\n\n   \n# here\n", "1:1", &["empty tree"]);
}

#[test]
fn unknown_node_kind_lists_the_valid_kinds() {
    assert_refused(
        "OR 1\n- XOR 1\n",
        "2:3",
        &["unknown node kind `XOR`", "OR, AND, OR*, AND*, LOR, PAR, NOT", "REPEAT, RETRY"],
    );
}

#[test]
fn kinds_are_case_sensitive() {
    assert_refused("or 1\n- A-rotate 0\n", "1:1", &["unknown node kind `or`"]);
}

#[test]
fn unknown_condition_lists_the_catalog_conditions() {
    assert_refused(
        "AND 1\n- C-seesTarget 0\n",
        "2:3",
        &["unknown condition `seesTarget`", "expected one of seeTarget"],
    );
}

#[test]
fn condition_prefix_does_not_reach_actions() {
    assert_refused("AND 1\n- C-rotate 0\n", "2:3", &["unknown condition `rotate`"]);
}

#[test]
fn leaf_without_a_name_is_refused() {
    assert_refused("AND 1\n- A- 0\n", "2:3", &["expected a leaf name after `A-`"]);
}

#[test]
fn depth_jump_of_more_than_one_is_refused() {
    assert_refused(
        "OR 1\n- AND 1\n--- A-rotate 0\n",
        "3:1",
        &["depth jumps from 1 to 3", "at most one level deeper", "(line 2)"],
    );
}

#[test]
fn missing_children_are_reported_at_the_parent() {
    assert_refused(
        "OR 3\n- A-rotate 0\n- A-elevate 0\n",
        "1:4",
        &["OR declares 3 children but has 2"],
    );
}

#[test]
fn missing_children_of_an_inner_node_are_reported_when_it_closes() {
    assert_refused(
        "OR 2\n- AND 2\n-- A-rotate 0\n- A-elevate 0\n",
        "2:7",
        &["AND declares 2 children but has 1"],
    );
}

#[test]
fn extra_children_are_reported_at_the_parent() {
    assert_refused(
        "OR 1\n- A-rotate 0\n- A-elevate 0\n",
        "1:4",
        &["OR declares 1 child but has 2"],
    );
}

#[test]
fn child_of_a_leaf_is_reported_at_the_leaf() {
    assert_refused(
        "OR 1\n- A-rotate 0\n-- A-elevate 0\n",
        "2:12",
        &["A-rotate declares 0 children but has 1"],
    );
}

#[test]
fn second_root_is_refused() {
    assert_refused(
        "OR 1\n- A-rotate 0\nAND 1\n- A-elevate 0\n",
        "3:1",
        &["more than one root", "root is on line 1"],
    );
}

#[test]
fn missing_root_is_refused() {
    assert_refused("- OR 1\n-- A-rotate 0\n", "1:1", &["missing root", "found depth 1"]);
}

#[test]
fn indentation_with_spaces_is_refused() {
    assert_refused("OR 1\n  - A-rotate 0\n", "2:1", &["unexpected indentation", "leading dashes"]);
}

#[test]
fn dashes_must_be_followed_by_a_space() {
    assert_refused("OR 1\n-A-rotate 0\n", "2:2", &["expected a space after the depth dashes"]);
}

#[test]
fn dashes_without_a_kind_are_refused() {
    assert_refused("OR 1\n- # no kind\n", "2:3", &["expected a node kind after the depth dashes"]);
}

#[test]
fn missing_child_count_is_refused() {
    assert_refused("OR\n", "1:4", &["expected the number of children after `OR`"]);
}

#[test]
fn non_numeric_child_count_is_refused() {
    assert_refused(
        "OR two\n",
        "1:4",
        &["expected the number of children (a non-negative integer), found `two`"],
    );
}

#[test]
fn negative_child_count_is_refused() {
    assert_refused("OR -1\n", "1:4", &["non-negative integer", "found `-1`"]);
}

#[test]
fn huge_child_count_is_refused() {
    assert_refused("OR 99999999999999999999999\n", "1:4", &["too large"]);
}

#[test]
fn leaf_declaring_children_is_refused() {
    assert_refused(
        "OR 1\n- A-rotate 2\n",
        "2:12",
        &["a leaf has no children", "expected `A-rotate 0`, found 2"],
    );
}

#[test]
fn composite_without_children_is_refused() {
    assert_refused("LOR 0\n", "1:5", &["`LOR` needs at least one child, found 0"]);
}

#[test]
fn decorator_with_two_children_is_refused() {
    assert_refused(
        "NOT 2\n- A-rotate 0\n- A-elevate 0\n",
        "1:5",
        &["`NOT` takes exactly 1 child, found 2"],
    );
}

#[test]
fn repeat_without_n_is_refused() {
    assert_refused(
        "REPEAT 1\n- A-rotate 0\n",
        "1:1",
        &["`REPEAT` needs a parameter `n=N`", "1 <= N <= 1000"],
    );
}

#[test]
fn retry_with_zero_attempts_is_refused() {
    assert_refused(
        "RETRY 1 n=0\n- A-rotate 0\n",
        "1:9",
        &["`n=0` is out of range: expected 1 <= n <= 1000"],
    );
}

#[test]
fn repeat_beyond_the_cap_is_refused() {
    assert_refused("REPEAT 1 n=1001\n- A-rotate 0\n", "1:10", &["out of range", "n <= 1000"]);
}

#[test]
fn par_threshold_beyond_its_children_is_refused() {
    assert_refused(
        "PAR 2 m=3\n- A-rotate 0\n- A-elevate 0\n",
        "1:7",
        &["`m=3` is out of range: expected 1 <= m <= 2"],
    );
}

#[test]
fn huge_parameter_is_out_of_range() {
    assert_refused("REPEAT 1 n=99999999999999999999999\n- A-rotate 0\n", "1:10", &["out of range"]);
}

#[test]
fn non_numeric_parameter_is_refused() {
    assert_refused(
        "PAR 2 m=two\n- A-rotate 0\n- A-elevate 0\n",
        "1:7",
        &["expected a positive integer for `m`, found `two`"],
    );
}

#[test]
fn parameter_without_equals_is_refused() {
    assert_refused(
        "PAR 2 m2\n- A-rotate 0\n- A-elevate 0\n",
        "1:7",
        &["expected a `key=value` parameter, found `m2`"],
    );
}

#[test]
fn unknown_parameter_key_is_refused() {
    assert_refused(
        "PAR 2 n=1\n- A-rotate 0\n- A-elevate 0\n",
        "1:7",
        &["unknown parameter `n` for `PAR`; expected `m`"],
    );
}

#[test]
fn parameter_on_a_kind_without_parameters_is_refused() {
    assert_refused("OR 1 m=1\n- A-rotate 0\n", "1:6", &["`OR` takes no parameters, found `m=1`"]);
}

#[test]
fn parameter_given_twice_is_refused() {
    assert_refused(
        "PAR 2 m=1 m=2\n- A-rotate 0\n- A-elevate 0\n",
        "1:11",
        &["parameter `m` is given twice"],
    );
}

#[test]
fn hash_inside_a_field_is_not_a_comment() {
    assert_refused("OR 1#x\n- A-rotate 0\n", "1:4", &["found `1#x`"]);
}

/// A chain of `NOT`s ending in a leaf at `depth`.
fn chain(depth: usize) -> String {
    let mut text = String::new();
    for level in 0..depth {
        text.push_str(&format!("{}NOT 1\n", dashes(level)));
    }
    text.push_str(&format!("{}A-rotate 0\n", dashes(depth)));
    text
}

fn dashes(depth: usize) -> String {
    match depth {
        0 => String::new(),
        _ => format!("{} ", "-".repeat(depth)),
    }
}

#[test]
fn deepest_allowed_tree_parses_and_renders() {
    let tree = parse_ok(&chain(MAX_DEPTH));
    assert_eq!(parse_ok(&to_text(&tree)), tree);
    assert_eq!(render_ascii(&tree).lines().count(), MAX_DEPTH + 1);
}

#[test]
fn tree_deeper_than_the_limit_is_refused() {
    let line = MAX_DEPTH + 2;
    assert_refused(
        &chain(MAX_DEPTH + 1),
        &format!("{line}:1"),
        &["depth 257 exceeds the limit of 256"],
    );
}

#[test]
fn tree_with_too_many_nodes_is_refused() {
    let mut text = format!("AND {MAX_NODES}\n");
    text.push_str(&"- A-rotate 0\n".repeat(MAX_NODES));
    let line = MAX_NODES + 1;
    assert_refused(&text, &format!("{line}:1"), &["more than 100000 nodes"]);
}
