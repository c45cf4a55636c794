//! A [`TreeSpec`] written back out: as the text format, and as a drawing for people.
//!
//! [`to_text`] writes the canonical form of the text format that [`parse_tree`] reads: one
//! space between fields, the child count as it is, `PAR`'s `m` always written, no comments.
//! Parsing it gives the same tree back, with nodes numbered from line 1 in pre-order.
//!
//! [`render_ascii`] draws the tree for `agent bt show`, with box-drawing characters and each
//! node's parameter, and the node's source line in a right-aligned gutter so a reader can go
//! from the drawing to the file. Fig. 5 of the thesis, parsed from its text, draws as:
//!
//! ```text
//!  1  OR
//!  2  ├── AND
//!  3  │   ├── C-seeTarget
//!  4  │   └── A-endEpisode
//!  5  └── LOR
//!  6      ├── A-rotate
//!  7      ├── A-elevate
//!  8      ├── A-rotate
//!  9      ├── A-deElevate
//! 10      └── A-waypointTranslation
//! ```
//!
//! Parameters follow the kind (`PAR m=2`, `REPEAT n=3`); the child count is left out, the
//! drawing shows it. Both outputs end every line, the last included, with `\n`.
//!
//! [`parse_tree`]: super::parse::parse_tree

use super::spec::{NodeSpec, TreeSpec};

/// The tree in the canonical text format.
///
/// A tree built in code rather than parsed reads back only if it is one the parser accepts
/// (leaf names in the catalog, child counts that fit the kinds, parameters in range).
pub fn to_text(tree: &TreeSpec) -> String {
    let mut out = String::new();
    write_text(&tree.root, 0, &mut out);
    out
}

fn write_text(node: &NodeSpec, depth: usize, out: &mut String) {
    if depth > 0 {
        out.push_str(&"-".repeat(depth));
        out.push(' ');
    }
    out.push_str(&format!("{} {}{}\n", node.kind, node.children.len(), node.kind.param_suffix()));
    for child in &node.children {
        write_text(child, depth + 1, out);
    }
}

/// The tree drawn with box-drawing characters, one node a line, source lines in a gutter.
pub fn render_ascii(tree: &TreeSpec) -> String {
    let width = max_line(&tree.root).to_string().len();
    let mut out = String::new();
    write_ascii(&tree.root, width, "", "", &mut out);
    out
}

/// Draws `node` after `branch` (its own connector), its children after `indent`.
fn write_ascii(node: &NodeSpec, width: usize, branch: &str, indent: &str, out: &mut String) {
    out.push_str(&format!("{:>width$}  {branch}{}\n", node.line, node.kind.label()));
    let last = node.children.len().saturating_sub(1);
    for (index, child) in node.children.iter().enumerate() {
        let (own, below) =
            if index == last { ("└── ", "    ") } else { ("├── ", "│   ") };
        let (child_branch, child_indent) = (format!("{indent}{own}"), format!("{indent}{below}"));
        write_ascii(child, width, &child_branch, &child_indent, out);
    }
}

fn max_line(node: &NodeSpec) -> usize {
    node.children.iter().map(max_line).fold(node.line, usize::max)
}
