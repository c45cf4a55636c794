//! The `.map` parser.
//!
//! Two passes: the first reads the lines in any order and checks their syntax, the second
//! checks that the pieces fit together (grid against `size:`, waypoints against the grid,
//! facts against the routes). Every token keeps its line and column, so each refusal points
//! at the offending text, whichever pass finds it.

use std::collections::BTreeMap;

use flockstep_proto::limits::{MAX_AGENTS, MAX_TARGETS, MAX_WAYPOINTS};
use flockstep_proto::{Heading, Height, Pose};

use super::{pose_key, target_label, uav_name, Cell, Expect, MapFile};
use crate::error::{MapError, MapErrorKind};

/// A whitespace-separated word and its 1-based column.
#[derive(Debug, Clone, Copy)]
struct Tok<'a> {
    col: usize,
    text: &'a str,
}

/// A pose as written: the waypoint token (for positions) and its 1-based number.
struct RawPose<'a> {
    at: Tok<'a>,
    wp: usize,
    height: Height,
    heading: Heading,
}

struct RawRoute<'a> {
    line: usize,
    name: Tok<'a>,
    waypoints: Vec<(Tok<'a>, usize, usize)>,
}

struct RawExpect<'a> {
    line: usize,
    uav: Tok<'a>,
    target: Tok<'a>,
    poses: Vec<RawPose<'a>>,
}

/// A grid row: its line and its tokens.
type RawRow<'a> = (usize, Vec<Tok<'a>>);

/// What the first pass found; each header item keeps its line.
#[derive(Default)]
struct Raw<'a> {
    name: Option<(usize, String)>,
    size: Option<(usize, usize, usize)>,
    start: Option<(usize, RawPose<'a>)>,
    grid: Option<(usize, Vec<RawRow<'a>>)>,
    routes: Vec<RawRoute<'a>>,
    expects: Vec<RawExpect<'a>>,
}

const KEYWORDS: [&str; 6] = ["name", "size", "start", "grid", "route", "expect"];

/// How a keyword's line reads, for messages.
fn shape(key: &str) -> &'static str {
    match key {
        "name" => "`name: <text>`",
        "size" => "`size: <rows> <cols>`",
        "start" => "`start: wp<k> <low|high> <N|E|S|W>`",
        "grid" => "`grid:` followed by the rows",
        "route" => "`route UAV<k>: <row>,<col> ...`",
        _ => "`expect UAV<k> T<k>: <wp> <low|high> <N|E|S|W>, ...` or `expect UAV<k> T<k>: none`",
    }
}

/// Splits `text` into words; `base_col` is the column of `text`'s first character.
fn tokenize(text: &str, base_col: usize) -> Vec<Tok<'_>> {
    let mut toks = Vec::new();
    let mut open: Option<(usize, usize)> = None;
    for (n, (i, c)) in text.char_indices().enumerate() {
        if c.is_whitespace() {
            if let Some((b, col)) = open.take() {
                toks.push(Tok { col, text: &text[b..i] });
            }
        } else if open.is_none() {
            open = Some((i, base_col + n));
        }
    }
    if let Some((b, col)) = open {
        toks.push(Tok { col, text: &text[b..] });
    }
    toks
}

/// 1-based column of byte offset `byte` of `line`.
fn col_of(line: &str, byte: usize) -> usize {
    line.get(..byte).map_or(1, |s| s.chars().count() + 1)
}

/// `found` of a message: the token, or what ends the text where a token was expected.
fn found(tok: Option<&Tok>, end: &str) -> String {
    tok.map_or_else(|| end.to_string(), |t| format!("`{}`", t.text))
}

fn syntax(expected: impl Into<String>, tok: Option<&Tok>) -> MapErrorKind {
    syntax_before(expected, tok, "end of line")
}

/// A syntax error in a piece of a line that ends with `end` (e.g. a `,`).
fn syntax_before(expected: impl Into<String>, tok: Option<&Tok>, end: &str) -> MapErrorKind {
    MapErrorKind::Syntax { expected: expected.into(), found: found(tok, end) }
}

/// `prefix<k>` with k >= 1 written without sign or leading zeros, e.g. `T3`, `UAV2`, `wp6`.
fn numbered(text: &str, prefix: &str) -> Option<usize> {
    let k: usize = text.strip_prefix(prefix)?.parse().ok()?;
    (k >= 1 && text == format!("{prefix}{k}")).then_some(k)
}

/// Parses the text of a `.map` file; `file` names it in errors (`file:line:col: ...`).
pub fn parse_map(file: &str, text: &str) -> Result<MapFile, MapError> {
    let n_lines = text.lines().count().max(1);
    let parser = Parser { file, n_lines };
    let raw = parser.read_lines(text)?;
    parser.assemble(raw)
}

struct Parser<'f> {
    file: &'f str,
    n_lines: usize,
}

impl Parser<'_> {
    fn err(&self, line: usize, col: usize, kind: MapErrorKind) -> MapError {
        MapError { file: self.file.to_string(), line, col, kind }
    }

    /// First pass: classify every line and check its own syntax.
    fn read_lines<'a>(&self, text: &'a str) -> Result<Raw<'a>, MapError> {
        let mut raw = Raw::default();
        // Rows follow `grid:` until the next keyword line.
        let mut in_grid = false;
        for (i, full) in text.lines().enumerate() {
            let line = i + 1;
            let content = full.split('#').next().unwrap_or_default();
            let toks = tokenize(content, 1);
            let Some(first) = toks.first() else { continue };
            let key = first.text.split(':').next().unwrap_or_default();
            if !KEYWORDS.contains(&key) {
                match raw.grid.as_mut() {
                    Some((_, rows)) if in_grid => rows.push((line, toks)),
                    _ => {
                        let kind = MapErrorKind::UnknownLine { found: first.text.to_string() };
                        return Err(self.err(line, first.col, kind));
                    }
                }
                continue;
            }
            in_grid = key == "grid";
            self.keyword_line(&mut raw, line, content, key, &toks)?;
        }
        Ok(raw)
    }

    /// One `key ...: body` line.
    fn keyword_line<'a>(
        &self,
        raw: &mut Raw<'a>,
        line: usize,
        content: &'a str,
        key: &str,
        toks: &[Tok<'a>],
    ) -> Result<(), MapError> {
        let n_head = match key {
            "route" => 2,
            "expect" => 3,
            _ => 1,
        };
        let end_col = col_of(content, content.trim_end().len());
        let Some(colon) = content.find(':') else {
            let tok = toks.get(n_head);
            let col = tok.map_or(end_col, |t| t.col);
            return Err(self.err(line, col, syntax(format!("`:` as in {}", shape(key)), tok)));
        };
        let head = tokenize(&content[..colon], 1);
        if head.len() != n_head {
            let col = head.get(n_head).map_or(col_of(content, colon), |t| t.col);
            let kind = syntax(shape(key), head.get(n_head).or(head.last()));
            return Err(self.err(line, col, kind));
        }
        let body_col = col_of(content, colon + 1);
        let body = &content[colon + 1..];
        let toks = tokenize(body, body_col);
        match key {
            "name" => {
                self.once("name:", raw.name.as_ref().map(|n| n.0), line)?;
                let name = body.trim();
                if name.is_empty() {
                    return Err(self.err(line, end_col, syntax("a name after `name:`", None)));
                }
                raw.name = Some((line, name.to_string()));
            }
            "size" => {
                self.once("size:", raw.size.map(|s| s.0), line)?;
                let rows = self.positive(line, toks.first(), end_col, "the number of rows")?;
                let cols = self.positive(line, toks.get(1), end_col, "the number of columns")?;
                self.end(line, toks.get(2), "end of line after `size: <rows> <cols>`")?;
                raw.size = Some((line, rows, cols));
            }
            "start" => {
                self.once("start:", raw.start.as_ref().map(|s| s.0), line)?;
                let pose = self.pose(line, &toks, (end_col, "end of line"))?;
                self.end(line, toks.get(3), "end of line after the start pose")?;
                raw.start = Some((line, pose));
            }
            "grid" => {
                self.once("grid:", raw.grid.as_ref().map(|g| g.0), line)?;
                let expected = "end of line after `grid:` (the rows follow on their own lines)";
                self.end(line, toks.first(), expected)?;
                raw.grid = Some((line, Vec::new()));
            }
            "route" => raw.routes.push(self.route(line, head[1], &toks, raw.routes.len())?),
            _ => raw.expects.push(self.expect(line, head[1], head[2], content, colon + 1)?),
        }
        Ok(())
    }

    /// Refuses a second `item` line.
    fn once(&self, item: &'static str, first: Option<usize>, line: usize) -> Result<(), MapError> {
        match first {
            Some(first) => Err(self.err(line, 1, MapErrorKind::Duplicate { item, first })),
            None => Ok(()),
        }
    }

    /// Refuses anything left on the line.
    fn end(&self, line: usize, extra: Option<&Tok>, expected: &str) -> Result<(), MapError> {
        match extra {
            Some(tok) => Err(self.err(line, tok.col, syntax(expected, Some(tok)))),
            None => Ok(()),
        }
    }

    fn positive(
        &self,
        line: usize,
        tok: Option<&Tok>,
        end_col: usize,
        what: &str,
    ) -> Result<usize, MapError> {
        match tok.and_then(|t| t.text.parse::<usize>().ok()) {
            Some(n) if n >= 1 => Ok(n),
            _ => {
                let col = tok.map_or(end_col, |t| t.col);
                Err(self.err(line, col, syntax(format!("{what} (an integer >= 1)"), tok)))
            }
        }
    }

    /// `<wp> <low|high> <N|E|S|W>`; the waypoint may be written `wp6` or `6`. `end` is
    /// the column and the description of what follows the pose.
    fn pose<'a>(
        &self,
        line: usize,
        toks: &[Tok<'a>],
        end: (usize, &str),
    ) -> Result<RawPose<'a>, MapError> {
        let at = |i: usize| toks.get(i).map_or(end.0, |t| t.col);
        let syntax = |expected: &str, i: usize| syntax_before(expected, toks.get(i), end.1);
        let wp_tok = toks.first();
        let wp = wp_tok.and_then(|t| {
            numbered(t.text, "wp").or_else(|| numbered(&format!("wp{}", t.text), "wp"))
        });
        let (Some(&tok), Some(wp)) = (wp_tok, wp) else {
            let kind = syntax("a waypoint number >= 1 (`wp6` or `6`)", 0);
            return Err(self.err(line, at(0), kind));
        };
        let Some(height) = toks.get(1).and_then(|t| Height::parse(t.text)) else {
            return Err(self.err(line, at(1), syntax("a height `low` or `high`", 1)));
        };
        let Some(heading) = toks.get(2).and_then(|t| Heading::parse(t.text)) else {
            return Err(self.err(line, at(2), syntax("a heading `N`, `E`, `S` or `W`", 2)));
        };
        Ok(RawPose { at: tok, wp, height, heading })
    }

    /// `route UAV<k>: r,c r,c ...`; routes must be named in order.
    fn route<'a>(
        &self,
        line: usize,
        name: Tok<'a>,
        toks: &[Tok<'a>],
        index: usize,
    ) -> Result<RawRoute<'a>, MapError> {
        let expected = uav_name(index);
        if name.text != expected {
            let kind = MapErrorKind::RouteName { expected, found: name.text.to_string() };
            return Err(self.err(line, name.col, kind));
        }
        let mut waypoints = Vec::with_capacity(toks.len());
        for tok in toks {
            let cell = tok
                .text
                .split_once(',')
                .and_then(|(r, c)| Some((r.parse::<usize>().ok()?, c.parse::<usize>().ok()?)));
            let Some((row, col)) = cell else {
                let kind = syntax("a waypoint `row,col` (0-based integers)", Some(tok));
                return Err(self.err(line, tok.col, kind));
            };
            waypoints.push((*tok, row, col));
        }
        Ok(RawRoute { line, name, waypoints })
    }

    /// `expect UAV<k> T<k>: pose, pose, ...` or `...: none`; `body` is a byte offset.
    fn expect<'a>(
        &self,
        line: usize,
        uav: Tok<'a>,
        target: Tok<'a>,
        content: &'a str,
        body: usize,
    ) -> Result<RawExpect<'a>, MapError> {
        let mut poses = Vec::new();
        let toks = tokenize(&content[body..], col_of(content, body));
        if !(toks.len() == 1 && toks[0].text == "none") {
            // Each comma-separated part is one pose; its end column is where the comma is.
            let mut from = body;
            let parts: Vec<&str> = content[body..].split(',').collect();
            for (i, part) in parts.iter().enumerate() {
                let to = from + part.len();
                let toks = tokenize(part, col_of(content, from));
                let end = if i + 1 < parts.len() { "`,`" } else { "end of line" };
                let pose = self.pose(line, &toks, (col_of(content, to), end))?;
                let expected = "`,` or end of line after the pose";
                self.end(line, toks.get(3), expected)?;
                poses.push(pose);
                from = to + 1;
            }
        }
        Ok(RawExpect { line, uav, target, poses })
    }

    /// Second pass: check that the pieces fit together and build the map.
    fn assemble(&self, raw: Raw) -> Result<MapFile, MapError> {
        let missing = |item, key| {
            let kind = MapErrorKind::Missing { item, expected: shape(key) };
            self.err(self.n_lines, 1, kind)
        };
        let (_, name) = raw.name.ok_or_else(|| missing("name:", "name"))?;
        let (_, rows, cols) = raw.size.ok_or_else(|| missing("size:", "size"))?;
        let (start_line, start) = raw.start.ok_or_else(|| missing("start:", "start"))?;
        let (grid_line, grid) = raw.grid.ok_or_else(|| missing("grid:", "grid"))?;
        let mut map = MapFile {
            name,
            rows,
            cols,
            cells: Vec::new(),
            targets: Vec::new(),
            target_at: Vec::new(),
            routes: Vec::new(),
            // Set below, once the start waypoint is known to be on every route.
            start: Pose::default(),
            expects: Vec::new(),
        };
        self.grid(&mut map, grid_line, &grid)?;
        self.routes(&mut map, &raw.routes)?;
        for (uav, route) in map.routes.iter().enumerate() {
            if start.wp > route.len() {
                let (wp, len) = (start.wp, route.len());
                let kind = MapErrorKind::BeyondRoute {
                    what: "start waypoint",
                    wp,
                    uav: uav_name(uav),
                    len,
                };
                return Err(self.err(start_line, start.at.col, kind));
            }
        }
        map.start = Pose::new(start.wp - 1, start.height, start.heading);
        for fact in &raw.expects {
            let expect = self.fact(&map, fact)?;
            if let Some(first) =
                map.expects.iter().find(|e| (e.uav, e.target) == (expect.uav, expect.target))
            {
                let kind = MapErrorKind::DuplicateExpect {
                    uav: uav_name(expect.uav),
                    target: target_label(expect.target),
                    first: first.line,
                };
                return Err(self.err(fact.line, fact.uav.col, kind));
            }
            map.expects.push(expect);
        }
        Ok(map)
    }

    /// The grid rows: cells, targets by label, and where each label is written.
    fn grid(&self, map: &mut MapFile, grid_line: usize, grid: &[RawRow]) -> Result<(), MapError> {
        let (rows, cols) = (map.rows, map.cols);
        if grid.len() != rows {
            // Too many rows: point at the first extra one; too few: at `grid:`.
            let line = grid.get(rows).map_or(grid_line, |r| r.0);
            return Err(self.err(
                line,
                1,
                MapErrorKind::GridRows { expected: rows, found: grid.len() },
            ));
        }
        // Label number -> (row, col, line, column).
        let mut labels: BTreeMap<usize, (usize, usize, usize, usize)> = BTreeMap::new();
        for (row, (line, toks)) in grid.iter().enumerate() {
            if toks.len() != cols {
                // Too many cells: point at the first extra one; too few: after the last.
                let after_last = toks.last().map_or(1, |t| t.col + t.text.chars().count());
                let col = toks.get(cols).map_or(after_last, |t| t.col);
                let kind = MapErrorKind::RaggedRow { expected: cols, found: toks.len() };
                return Err(self.err(*line, col, kind));
            }
            for (col, tok) in toks.iter().enumerate() {
                let cell = match tok.text {
                    "." => Cell::Free,
                    "X" => Cell::Occlusion,
                    text => {
                        let Some(k) = numbered(text, "T") else {
                            let kind = MapErrorKind::UnknownCell { token: text.to_string() };
                            return Err(self.err(*line, tok.col, kind));
                        };
                        if let Some(&(_, _, l, c)) = labels.get(&k) {
                            let kind = MapErrorKind::DuplicateTarget {
                                label: target_label(k - 1),
                                line: l,
                                col: c,
                            };
                            return Err(self.err(*line, tok.col, kind));
                        }
                        if k > MAX_TARGETS {
                            let kind = MapErrorKind::TooMany {
                                what: "targets",
                                found: k,
                                max: MAX_TARGETS,
                            };
                            return Err(self.err(*line, tok.col, kind));
                        }
                        labels.insert(k, (row, col, *line, tok.col));
                        Cell::Free
                    }
                };
                map.cells.push(cell);
            }
        }
        let Some((&highest, &(_, _, line, col))) = labels.last_key_value() else {
            return Err(self.err(grid_line, 1, MapErrorKind::NoTargets));
        };
        if let Some(missing) = (1..highest).find(|k| !labels.contains_key(k)) {
            return Err(self.err(line, col, MapErrorKind::TargetGap { missing, highest }));
        }
        map.targets = labels.values().map(|&(r, c, _, _)| (r, c)).collect();
        map.target_at = labels.values().map(|&(_, _, l, c)| (l, c)).collect();
        Ok(())
    }

    /// The routes: within the limits, every waypoint a free cell of the grid.
    fn routes(&self, map: &mut MapFile, routes: &[RawRoute]) -> Result<(), MapError> {
        if routes.is_empty() {
            return Err(self.err(self.n_lines, 1, MapErrorKind::NoRoutes));
        }
        if let Some(extra) = routes.get(MAX_AGENTS) {
            let kind =
                MapErrorKind::TooMany { what: "routes", found: routes.len(), max: MAX_AGENTS };
            return Err(self.err(extra.line, 1, kind));
        }
        for route in routes {
            if route.waypoints.is_empty() {
                let kind = MapErrorKind::NoWaypoints { uav: route.name.text.to_string() };
                return Err(self.err(route.line, route.name.col, kind));
            }
            if let Some((extra, _, _)) = route.waypoints.get(MAX_WAYPOINTS) {
                let found = route.waypoints.len();
                let kind = MapErrorKind::TooMany { what: "waypoints", found, max: MAX_WAYPOINTS };
                return Err(self.err(route.line, extra.col, kind));
            }
            let mut cells = Vec::with_capacity(route.waypoints.len());
            for &(tok, row, col) in &route.waypoints {
                let kind = match map.cell(row, col) {
                    None => MapErrorKind::OffGrid { row, col, rows: map.rows, cols: map.cols },
                    Some(Cell::Occlusion) => MapErrorKind::OnOcclusion { row, col },
                    Some(Cell::Free) => {
                        cells.push((row, col));
                        continue;
                    }
                };
                return Err(self.err(route.line, tok.col, kind));
            }
            map.routes.push(cells);
        }
        Ok(())
    }

    /// One `expect` line against the routes and targets.
    fn fact(&self, map: &MapFile, fact: &RawExpect) -> Result<Expect, MapError> {
        let n = map.routes.len();
        let Some(uav) = numbered(fact.uav.text, "UAV").filter(|&k| k <= n).map(|k| k - 1) else {
            let kind = MapErrorKind::UnknownUav { name: fact.uav.text.to_string(), n };
            return Err(self.err(fact.line, fact.uav.col, kind));
        };
        let n = map.targets.len();
        let Some(target) = numbered(fact.target.text, "T").filter(|&k| k <= n).map(|k| k - 1)
        else {
            let kind = MapErrorKind::UnknownTarget { label: fact.target.text.to_string(), n };
            return Err(self.err(fact.line, fact.target.col, kind));
        };
        let len = map.routes[uav].len();
        let mut poses: Vec<Pose> = Vec::with_capacity(fact.poses.len());
        for raw in &fact.poses {
            if raw.wp > len {
                let kind =
                    MapErrorKind::BeyondRoute { what: "pose", wp: raw.wp, uav: uav_name(uav), len };
                return Err(self.err(fact.line, raw.at.col, kind));
            }
            let pose = Pose::new(raw.wp - 1, raw.height, raw.heading);
            if poses.contains(&pose) {
                let kind = MapErrorKind::DuplicatePose { pose: pose.to_string() };
                return Err(self.err(fact.line, raw.at.col, kind));
            }
            poses.push(pose);
        }
        poses.sort_by_key(pose_key);
        Ok(Expect { uav, target, poses, line: fact.line })
    }
}
