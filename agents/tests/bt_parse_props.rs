//! Property tests of the behavior-tree parser: whatever the text, `parse_tree` answers Ok or
//! a located error and never panics, and every tree it accepts round-trips through `to_text`.
//!
//! Random strings rarely get past the first token, so most inputs are built to come close:
//! soups of valid tokens, and valid trees with their lines mutated the way a hand edit goes
//! wrong (a line deleted, duplicated or moved, a dash or a count off, a parameter mangled).

use flockstep_agents::bt::parse::{parse_tree, ParseError};
use flockstep_agents::bt::render::{render_ascii, to_text};
use flockstep_agents::bt::spec::{LeafCatalog, LeafKind, NodeKind, NodeSpec, TreeSpec};
use proptest::prelude::*;
use proptest::sample::{select, Index};

/// The product's catalog of UAV leaves (thesis 3.3).
use flockstep_agents::uav::UavCatalog as Uav;

/// Kind tokens, valid and not, for the token soups.
const KINDS: [&str; 17] = [
    "OR",
    "AND",
    "OR*",
    "AND*",
    "LOR",
    "PAR",
    "NOT",
    "FORCE_SUCCESS",
    "FORCE_FAILURE",
    "REPEAT",
    "RETRY",
    "A-rotate",
    "A-endEpisode",
    "C-seeTarget",
    "A-",
    "C-fly",
    "XOR",
];
const COUNTS: [&str; 8] = ["0", "1", "2", "3", "x", "-1", "+2", "99999999999999999999999"];
const PARAMS: [&str; 12] =
    ["m=1", "m=2", "m=0", "n=1", "n=3", "n=0", "n=1001", "m", "=", "k=v", "n=+3", "#"];

/// Lines of characters the format uses, as a regex for proptest.
const FORMAT_ALPHABET: &str = "[-ORANDLPTFCEY_*=#mn0-9 \t\r\n]{0,120}";

fn parse(text: &str) -> Result<TreeSpec, ParseError> {
    parse_tree("p.bt", text, &Uav)
}

/// The property every input must satisfy: an accepted tree reads back the same from its
/// canonical text and draws one line per node; a refused one points inside the text.
fn check(text: &str) -> Result<(), TestCaseError> {
    match parse(text) {
        Ok(tree) => check_round_trip(&tree),
        Err(error) => check_location(text, &error),
    }
}

fn check_round_trip(tree: &TreeSpec) -> Result<(), TestCaseError> {
    let text = to_text(tree);
    let again = parse(&text).map_err(|error| TestCaseError::fail(error.to_string()))?;
    prop_assert_eq!(without_lines(again.root.clone()), without_lines(tree.root.clone()));
    prop_assert_eq!(to_text(&again), text);
    prop_assert_eq!(render_ascii(tree).lines().count(), count_nodes(&tree.root));
    Ok(())
}

fn check_location(text: &str, error: &ParseError) -> Result<(), TestCaseError> {
    let shown = error.to_string();
    let prefix = format!("p.bt:{}:{}: ", error.line, error.col);
    prop_assert!(shown.starts_with(&prefix), "{}", shown);
    prop_assert!(error.line >= 1 && error.col >= 1, "{}", shown);
    let line = text.lines().nth(error.line - 1).unwrap_or_default();
    // A missing field is pointed at just past the end of its line.
    prop_assert!(error.col <= line.chars().count() + 2, "{}", shown);
    prop_assert!(error.line <= text.lines().count().max(1), "{}", shown);
    Ok(())
}

fn without_lines(mut node: NodeSpec) -> NodeSpec {
    node.line = 0;
    node.children = node.children.into_iter().map(without_lines).collect();
    node
}

fn count_nodes(node: &NodeSpec) -> usize {
    1 + node.children.iter().map(count_nodes).sum::<usize>()
}

fn leaf() -> impl Strategy<Value = NodeSpec> {
    let action = select(Uav.names(LeafKind::Action)).prop_map(|name| NodeKind::Action {
        leaf: Uav.resolve(LeafKind::Action, &name).unwrap_or_default(),
        name,
    });
    let condition = select(Uav.names(LeafKind::Condition)).prop_map(|name| NodeKind::Condition {
        leaf: Uav.resolve(LeafKind::Condition, &name).unwrap_or_default(),
        name,
    });
    prop_oneof![3 => action, 1 => condition].prop_map(|kind| node(kind, vec![]))
}

fn node(kind: NodeKind, children: Vec<NodeSpec>) -> NodeSpec {
    NodeSpec { kind, children, line: 0 }
}

/// Valid trees of every kind, a few levels deep.
fn tree() -> impl Strategy<Value = TreeSpec> {
    let composite = select(vec![
        NodeKind::Fallback { memory: false },
        NodeKind::Fallback { memory: true },
        NodeKind::Sequence { memory: false },
        NodeKind::Sequence { memory: true },
        NodeKind::Learning,
    ]);
    let decorator = prop_oneof![
        select(vec![NodeKind::Inverter, NodeKind::ForceSuccess, NodeKind::ForceFailure]),
        (1u32..=1000).prop_map(|times| NodeKind::Repeat { times }),
        (1u32..=1000).prop_map(|attempts| NodeKind::Retry { attempts }),
    ];
    let root = leaf().prop_recursive(5, 40, 4, move |inner| {
        let children = prop::collection::vec(inner.clone(), 1..=4);
        prop_oneof![
            (composite.clone(), children.clone()).prop_map(|(kind, children)| node(kind, children)),
            (decorator.clone(), inner).prop_map(|(kind, child)| node(kind, vec![child])),
            (children, any::<Index>()).prop_map(|(children, threshold)| {
                let success_threshold = threshold.index(children.len()) + 1;
                node(NodeKind::Parallel { success_threshold }, children)
            }),
        ]
    });
    root.prop_map(|root| TreeSpec { source: "p.bt".to_owned(), root })
}

/// A line of valid tokens in a possibly wrong arrangement.
fn soup_line() -> impl Strategy<Value = String> {
    let dashes = prop_oneof![Just(String::new()), "-{1,4} ", Just("-".to_owned())];
    let params = prop::collection::vec(select(&PARAMS[..]), 0..=2);
    (dashes, select(&KINDS[..]), prop::option::weighted(0.9, select(&COUNTS[..])), params).prop_map(
        |(dashes, kind, count, params)| {
            let mut fields = vec![kind];
            fields.extend(count);
            fields.extend(params);
            format!("{dashes}{}", fields.join(" "))
        },
    )
}

/// One hand-editing mistake.
#[derive(Debug, Clone)]
enum Mutation {
    Delete(Index),
    Duplicate(Index),
    Swap(Index, Index),
    Dashes(Index, usize),
    Count(Index, &'static str),
    Param(Index, &'static str),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        any::<Index>().prop_map(Mutation::Delete),
        any::<Index>().prop_map(Mutation::Duplicate),
        (any::<Index>(), any::<Index>()).prop_map(|(a, b)| Mutation::Swap(a, b)),
        (any::<Index>(), 0..5usize).prop_map(|(at, depth)| Mutation::Dashes(at, depth)),
        (any::<Index>(), select(&COUNTS[..])).prop_map(|(at, count)| Mutation::Count(at, count)),
        (any::<Index>(), select(&PARAMS[..])).prop_map(|(at, param)| Mutation::Param(at, param)),
    ]
}

impl Mutation {
    fn apply(&self, lines: &mut Vec<String>) {
        if lines.is_empty() {
            return;
        }
        let len = lines.len();
        match self {
            Mutation::Delete(at) => {
                lines.remove(at.index(len));
            }
            Mutation::Duplicate(at) => {
                let line = lines[at.index(len)].clone();
                lines.insert(at.index(len), line);
            }
            Mutation::Swap(a, b) => lines.swap(a.index(len), b.index(len)),
            Mutation::Dashes(at, depth) => {
                let line = &mut lines[at.index(len)];
                let body = line.trim_start_matches(['-', ' ']).to_owned();
                *line = match depth {
                    0 => body,
                    _ => format!("{} {body}", "-".repeat(*depth)),
                };
            }
            Mutation::Count(at, count) => set_field(&mut lines[at.index(len)], 1, count),
            Mutation::Param(at, param) => set_field(&mut lines[at.index(len)], 2, param),
        }
    }
}

/// Replaces (or appends) the field at `index` after the dashes: 0 kind, 1 count, 2 parameter.
fn set_field(line: &mut String, index: usize, value: &str) {
    let body = line.trim_start_matches('-');
    let dashes = &line[..line.len() - body.len()];
    let mut fields: Vec<&str> = body.split_whitespace().collect();
    match fields.get_mut(index) {
        Some(field) => *field = value,
        None => fields.push(value),
    }
    let separator = if dashes.is_empty() { "" } else { " " };
    *line = format!("{dashes}{separator}{}", fields.join(" "));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(384))]

    #[test]
    fn valid_trees_round_trip(tree in tree()) {
        let text = to_text(&tree);
        let parsed = parse(&text).map_err(|error| TestCaseError::fail(error.to_string()))?;
        prop_assert_eq!(without_lines(parsed.root.clone()), tree.root);
        check_round_trip(&parsed)?;
    }

    #[test]
    fn arbitrary_strings_never_panic(text in any::<String>()) {
        check(&text)?;
    }

    #[test]
    fn strings_over_the_format_alphabet_never_panic(text in FORMAT_ALPHABET) {
        check(&text)?;
    }

    #[test]
    fn token_soups_never_panic(lines in prop::collection::vec(soup_line(), 0..12)) {
        check(&lines.join("\n"))?;
    }

    #[test]
    fn mutated_trees_never_panic(
        tree in tree(),
        mutations in prop::collection::vec(mutation(), 1..4),
    ) {
        let mut lines: Vec<String> = to_text(&tree).lines().map(str::to_owned).collect();
        for mutation in &mutations {
            mutation.apply(&mut lines);
        }
        check(&lines.join("\n"))?;
    }
}
