//! The behavior-tree text format (SPEC 1.1, thesis Fig. 5) read into a [`TreeSpec`].
//!
//! One node a line, in pre-order: a run of `-` giving the depth (none for the root), a
//! space, the kind, a space, the number of children, then optional `key=value` parameters:
//!
//! ```text
//! OR 2
//! - AND 2
//! -- C-seeTarget 0
//! -- A-endEpisode 0
//! - PAR 2 m=1   # a comment
//! -- A-rotate 0
//! -- A-elevate 0
//! ```
//!
//! Tree files are written by hand, so every mistake is reported as `source:line:col: message`
//! with what was expected, and no input can make the parser panic. Fields may be separated by
//! several spaces or tabs; columns count characters, a tab counting as one. Blank lines,
//! whole-line comments and comments after whitespace are skipped. Indenting a line with
//! spaces is refused rather than ignored, since it suggests the writer meant it as depth.
//! Depth and size are capped ([`MAX_DEPTH`], [`MAX_NODES`]) so that code walking the tree
//! recursively cannot overflow the stack.

use std::fmt::Display;
use std::str::FromStr;

use super::spec::{Arity, LeafCatalog, LeafKind, NodeKind, NodeSpec, TreeSpec};

/// The deepest node accepted (the root is at depth 0).
pub const MAX_DEPTH: usize = 256;
/// The most nodes a tree may have.
pub const MAX_NODES: usize = 100_000;
/// The largest `n` of `REPEAT` and `RETRY`.
pub const MAX_REPEAT: u32 = 1000;

const VALID_KINDS: &str = "OR, AND, OR*, AND*, LOR, PAR, NOT, FORCE_SUCCESS, FORCE_FAILURE, \
                           REPEAT, RETRY, C-<condition>, A-<action>";

/// A malformed tree file; displays as `source:line:col: message` (1-based line and column).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{file}:{line}:{col}: {message}")]
pub struct ParseError {
    /// The `source` given to [`parse_tree`], usually the file's path.
    pub file: String,
    pub line: usize,
    pub col: usize,
    pub message: String,
}

/// Parses a tree in the text format, resolving its leaves with `catalog`.
///
/// `source` names the text in error messages and in the result.
pub fn parse_tree(
    source: &str,
    text: &str,
    catalog: &dyn LeafCatalog,
) -> Result<TreeSpec, ParseError> {
    let error = |line, problem: Problem| ParseError {
        file: source.to_owned(),
        line,
        col: problem.col,
        message: problem.message,
    };
    // Editors on Windows may save a byte-order mark; it is invisible, so not worth an error.
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut builder = Builder::default();
    for (index, raw) in text.lines().enumerate() {
        let line = index + 1;
        if let Some(decl) = parse_line(raw, catalog).map_err(|problem| error(line, problem))? {
            builder.add(line, decl).map_err(|(at, problem)| error(at, problem))?;
        }
    }
    let root = builder.finish().map_err(|(at, problem)| error(at, problem))?;
    Ok(TreeSpec { source: source.to_owned(), root })
}

/// What is wrong, and the column it is at; the caller knows the line.
#[derive(Debug)]
struct Problem {
    col: usize,
    message: String,
}

impl Problem {
    fn at(col: usize, message: impl Into<String>) -> Self {
        Problem { col, message: message.into() }
    }
}

/// A problem reported at a line other than the one being read (a parent's child count).
type Located = (usize, Problem);

/// A whitespace-separated field of a line and the column it starts at.
#[derive(Debug, Clone, Copy)]
struct Token<'a> {
    text: &'a str,
    col: usize,
}

impl Token<'_> {
    /// The column just after this token.
    fn end(&self) -> usize {
        self.col + self.text.chars().count()
    }
}

/// The fields of `body`, whose first character is at column `first_col`, up to a comment.
fn tokens(body: &str, first_col: usize) -> impl Iterator<Item = Token<'_>> {
    let mut col = first_col;
    body.split([' ', '\t'])
        .filter_map(move |piece| {
            let token = Token { text: piece, col };
            col += piece.chars().count() + 1;
            (!piece.is_empty()).then_some(token)
        })
        .take_while(|token| !token.text.starts_with('#'))
}

/// One node line, checked on its own; its place in the tree is the [`Builder`]'s business.
#[derive(Debug)]
struct Decl {
    depth: usize,
    kind: NodeKind,
    children: usize,
    kind_col: usize,
    count_col: usize,
}

/// Reads one line: `None` for a blank or comment line.
fn parse_line(raw: &str, catalog: &dyn LeafCatalog) -> Result<Option<Decl>, Problem> {
    let line = raw.trim_end();
    let content = line.trim_start();
    if content.is_empty() || content.starts_with('#') {
        return Ok(None);
    }
    if content.len() != line.len() {
        return Err(Problem::at(
            1,
            "unexpected indentation: depth is given by leading dashes, e.g. `-- A-rotate 0`",
        ));
    }
    let body = line.trim_start_matches('-');
    // Dashes are one byte and one column each.
    let depth = line.len() - body.len();
    if depth > 0 && !body.starts_with([' ', '\t']) {
        return Err(Problem::at(depth + 1, "expected a space after the depth dashes"));
    }
    let mut fields = tokens(body, depth + 1);
    let kind_token = fields
        .next()
        .ok_or_else(|| Problem::at(depth + 2, "expected a node kind after the depth dashes"))?;
    let head = head(kind_token, catalog)?;
    let count_token = fields.next().ok_or_else(|| {
        let message = format!("expected the number of children after `{}`", kind_token.text);
        Problem::at(kind_token.end() + 1, message)
    })?;
    let children = child_count(count_token)?;
    check_arity(head.arity(), kind_token, count_token, children)?;
    let param = param(fields, kind_token, head.param_key())?;
    let kind = head.finish(kind_token, children, param)?;
    Ok(Some(Decl { depth, kind, children, kind_col: kind_token.col, count_col: count_token.col }))
}

/// A kind token, read before the child count its parameters may depend on.
enum Head {
    /// A kind without parameters, complete as written.
    Plain(NodeKind),
    Parallel,
    Repeat,
    Retry,
}

impl Head {
    fn arity(&self) -> Arity {
        match self {
            Head::Plain(kind) => kind.arity(),
            Head::Parallel => Arity::Many,
            Head::Repeat | Head::Retry => Arity::One,
        }
    }

    fn param_key(&self) -> Option<&'static str> {
        match self {
            Head::Plain(_) => None,
            Head::Parallel => Some("m"),
            Head::Repeat | Head::Retry => Some("n"),
        }
    }

    /// The node kind, once the child count and the (allowed) parameter are known.
    fn finish(
        self,
        kind_token: Token,
        children: usize,
        param: Option<Param>,
    ) -> Result<NodeKind, Problem> {
        let required = |param: Option<Param>| {
            let param = param.ok_or_else(|| {
                let message = format!(
                    "`{}` needs a parameter `n=N` with 1 <= N <= {MAX_REPEAT}",
                    kind_token.text
                );
                Problem::at(kind_token.col, message)
            })?;
            number(param, MAX_REPEAT)
        };
        Ok(match self {
            Head::Plain(kind) => kind,
            Head::Parallel => NodeKind::Parallel {
                // Without `m`, all children must succeed.
                success_threshold: param.map_or(Ok(children), |param| number(param, children))?,
            },
            Head::Repeat => NodeKind::Repeat { times: required(param)? },
            Head::Retry => NodeKind::Retry { attempts: required(param)? },
        })
    }
}

fn head(token: Token, catalog: &dyn LeafCatalog) -> Result<Head, Problem> {
    let kind = match token.text {
        "OR" => NodeKind::Fallback { memory: false },
        "OR*" => NodeKind::Fallback { memory: true },
        "AND" => NodeKind::Sequence { memory: false },
        "AND*" => NodeKind::Sequence { memory: true },
        "LOR" => NodeKind::Learning,
        "NOT" => NodeKind::Inverter,
        "FORCE_SUCCESS" => NodeKind::ForceSuccess,
        "FORCE_FAILURE" => NodeKind::ForceFailure,
        "PAR" => return Ok(Head::Parallel),
        "REPEAT" => return Ok(Head::Repeat),
        "RETRY" => return Ok(Head::Retry),
        _ => leaf(token, catalog)?,
    };
    Ok(Head::Plain(kind))
}

/// An `A-name` or `C-name` token, resolved in the catalog.
fn leaf(token: Token, catalog: &dyn LeafCatalog) -> Result<NodeKind, Problem> {
    let (kind, name) = [LeafKind::Action, LeafKind::Condition]
        .into_iter()
        .find_map(|kind| token.text.strip_prefix(kind.prefix()).map(|name| (kind, name)))
        .ok_or_else(|| {
            let message =
                format!("unknown node kind `{}`; expected one of {VALID_KINDS}", token.text);
            Problem::at(token.col, message)
        })?;
    if name.is_empty() {
        let message = format!("expected a leaf name after `{}`", kind.prefix());
        return Err(Problem::at(token.col, message));
    }
    let leaf = catalog.resolve(kind, name).ok_or_else(|| {
        let known = catalog.names(kind);
        let expected = if known.is_empty() {
            format!("the catalog has no {}s", kind.noun())
        } else {
            format!("expected one of {}", known.join(", "))
        };
        Problem::at(token.col, format!("unknown {} `{name}`; {expected}", kind.noun()))
    })?;
    let name = name.to_owned();
    Ok(match kind {
        LeafKind::Action => NodeKind::Action { leaf, name },
        LeafKind::Condition => NodeKind::Condition { leaf, name },
    })
}

fn child_count(token: Token) -> Result<usize, Problem> {
    if !is_digits(token.text) {
        let message = format!(
            "expected the number of children (a non-negative integer), found `{}`",
            token.text
        );
        return Err(Problem::at(token.col, message));
    }
    token.text.parse().map_err(|_| {
        Problem::at(token.col, format!("number of children `{}` is too large", token.text))
    })
}

/// `str::parse` also takes a leading `+`, which the format does not.
fn is_digits(text: &str) -> bool {
    !text.is_empty() && text.bytes().all(|byte| byte.is_ascii_digit())
}

fn check_arity(arity: Arity, kind: Token, count: Token, children: usize) -> Result<(), Problem> {
    let message = match arity {
        Arity::Leaf if children != 0 => {
            format!("a leaf has no children: expected `{} 0`, found {children}", kind.text)
        }
        Arity::One if children != 1 => {
            format!("`{}` takes exactly 1 child, found {children}", kind.text)
        }
        Arity::Many if children == 0 => {
            format!("`{}` needs at least one child, found 0", kind.text)
        }
        _ => return Ok(()),
    };
    Err(Problem::at(count.col, message))
}

/// A `key=value` field.
#[derive(Debug, Clone, Copy)]
struct Param<'a> {
    key: &'a str,
    value: &'a str,
    col: usize,
}

/// The parameter fields of a line; each kind admits at most one key, `allowed`.
fn param<'a>(
    fields: impl Iterator<Item = Token<'a>>,
    kind: Token,
    allowed: Option<&str>,
) -> Result<Option<Param<'a>>, Problem> {
    let mut found: Option<Param> = None;
    for field in fields {
        let (key, value) = field.text.split_once('=').ok_or_else(|| {
            let message = format!("expected a `key=value` parameter, found `{}`", field.text);
            Problem::at(field.col, message)
        })?;
        if Some(key) != allowed {
            let message = match allowed {
                None => format!("`{}` takes no parameters, found `{}`", kind.text, field.text),
                Some(allowed) => {
                    format!("unknown parameter `{key}` for `{}`; expected `{allowed}`", kind.text)
                }
            };
            return Err(Problem::at(field.col, message));
        }
        if found.is_some() {
            return Err(Problem::at(field.col, format!("parameter `{key}` is given twice")));
        }
        found = Some(Param { key, value, col: field.col });
    }
    Ok(found)
}

/// The parameter's value, which must be in `1..=max`.
fn number<T>(param: Param, max: T) -> Result<T, Problem>
where
    T: FromStr + PartialOrd + From<u8> + Display,
{
    let Param { key, value, col } = param;
    if !is_digits(value) {
        let message = format!("expected a positive integer for `{key}`, found `{value}`");
        return Err(Problem::at(col, message));
    }
    // Digits that do not fit in `T` are out of range too.
    value.parse().ok().filter(|number| *number >= T::from(1) && *number <= max).ok_or_else(|| {
        Problem::at(col, format!("`{key}={value}` is out of range: expected 1 <= {key} <= {max}"))
    })
}

/// A node whose children are still being read.
#[derive(Debug)]
struct Open {
    node: NodeSpec,
    declared: usize,
    count_col: usize,
}

/// Assembles node lines into a tree with a stack of the open path from the root.
#[derive(Debug, Default)]
struct Builder {
    /// `stack[d]` is the open node at depth `d`.
    stack: Vec<Open>,
    /// Line of the last node read.
    last_line: usize,
    nodes: usize,
}

impl Builder {
    fn add(&mut self, line: usize, decl: Decl) -> Result<(), Located> {
        self.check_place(&decl).map_err(|problem| (line, problem))?;
        self.close_until(decl.depth)?;
        if let Some(parent) = self.stack.last_mut() {
            if parent.node.children.len() == parent.declared {
                // One child too many: reported at the parent, like one too few.
                return Err(parent.count_problem(parent.declared + 1));
            }
        }
        self.last_line = line;
        self.nodes += 1;
        let node = NodeSpec { kind: decl.kind, children: Vec::new(), line };
        self.stack.push(Open { node, declared: decl.children, count_col: decl.count_col });
        Ok(())
    }

    /// Whether a node at `decl.depth` may follow the nodes read so far.
    fn check_place(&self, decl: &Decl) -> Result<(), Problem> {
        let depth = decl.depth;
        if depth > MAX_DEPTH {
            return Err(Problem::at(1, format!("depth {depth} exceeds the limit of {MAX_DEPTH}")));
        }
        if self.nodes == MAX_NODES {
            return Err(Problem::at(1, format!("the tree has more than {MAX_NODES} nodes")));
        }
        match self.stack.first().map(|root| root.node.line) {
            None if depth > 0 => Err(Problem::at(
                1,
                format!("missing root: the first node must have no dashes, found depth {depth}"),
            )),
            Some(root) if depth == 0 => Err(Problem::at(
                decl.kind_col,
                format!(
                    "more than one root: the root is on line {root}; \
                     every other node needs leading dashes"
                ),
            )),
            // The open path ends with the previous node, at depth `stack.len() - 1`.
            Some(_) if depth > self.stack.len() => Err(Problem::at(
                1,
                format!(
                    "depth jumps from {} to {depth}: a node can be at most one level deeper \
                     than the node before it (line {})",
                    self.stack.len().saturating_sub(1),
                    self.last_line
                ),
            )),
            _ => Ok(()),
        }
    }

    /// Closes open nodes until the deepest is at `depth - 1`, ready for a node at `depth`.
    /// The root is closed only by [`Builder::finish`].
    fn close_until(&mut self, depth: usize) -> Result<(), Located> {
        while self.stack.len() > depth.max(1) {
            let node = self.stack.pop().map(Open::close).transpose()?;
            if let (Some(node), Some(parent)) = (node, self.stack.last_mut()) {
                parent.node.children.push(node);
            }
        }
        Ok(())
    }

    fn finish(mut self) -> Result<NodeSpec, Located> {
        self.close_until(1)?;
        match self.stack.pop() {
            Some(root) => root.close(),
            None => Err((1, Problem::at(1, "empty tree: expected a root node such as `OR 2`"))),
        }
    }
}

impl Open {
    /// The finished node, which must have all the children it declared.
    fn close(self) -> Result<NodeSpec, Located> {
        if self.node.children.len() == self.declared {
            Ok(self.node)
        } else {
            Err(self.count_problem(self.node.children.len()))
        }
    }

    fn count_problem(&self, has: usize) -> Located {
        let declared = match self.declared {
            1 => "1 child".to_owned(),
            n => format!("{n} children"),
        };
        let message = format!("{} declares {declared} but has {has}", self.node.kind);
        (self.node.line, Problem::at(self.count_col, message))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fields(body: &str) -> Vec<(&str, usize)> {
        tokens(body, 1).map(|token| (token.text, token.col)).collect()
    }

    #[test]
    fn columns_count_characters_and_a_tab_as_one() {
        assert_eq!(fields("A-ärger\t2  m=1 # x"), [("A-ärger", 1), ("2", 9), ("m=1", 12)]);
    }

    #[test]
    fn a_hash_starts_a_comment_only_at_the_start_of_a_field() {
        assert_eq!(fields("1#x #y z"), [("1#x", 1)]);
    }

    #[test]
    fn only_plain_digits_are_numbers() {
        assert!(is_digits("0123"));
        assert!(!is_digits(""));
        assert!(!is_digits("+3"));
        assert!(!is_digits("-3"));
        assert!(!is_digits("３"));
    }

    #[test]
    fn digits_too_big_for_the_type_are_out_of_range() {
        let param = Param { key: "n", value: "4294967296", col: 7 };
        let problem = number(param, u32::MAX).expect_err("does not fit in u32");
        assert_eq!(problem.col, 7);
        assert!(problem.message.contains("out of range"), "{}", problem.message);
    }
}
