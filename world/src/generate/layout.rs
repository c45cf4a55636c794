//! Where the routes go: one sector of the grid per UAV, and a shared central square.
//!
//! The grid's rim (the square one cell inside the border) is cut into `uavs` equal arcs,
//! clockwise from the north-west corner; sector k is the wedge between the centre and arc
//! k. UAV k patrols its sector: out along one side of the wedge, along its arc of the rim,
//! back along the other side. It also inspects the central square (3x3 on grids under 24
//! cells, else 5x5) from waypoints just outside it, chosen near its own side so that the
//! high camera sees every cell of the square from at least one of them. So each region is
//! watched mostly by its own UAV and by its neighbours at the edges, and the central square
//! by every UAV: a target there is visible to all of them, from different poses.
//!
//! All geometry uses `+ - * /`, `sqrt` and rounding only (no trigonometry), which IEEE 754
//! makes identical on every machine, so the same seed gives the same map everywhere.

use flockstep_proto::{Heading, Height};
use rand_xoshiro::Xoshiro256PlusPlus;

use super::below;
use crate::visibility::in_footprint;

/// Target spacing of consecutive patrol waypoints, in cells.
const SPACING: f64 = 3.0;
/// Route length bounds (waypoints).
pub(super) const MIN_WAYPOINTS: usize = 4;
pub(super) const MAX_WAYPOINTS: usize = 12;
/// Most inspection waypoints a route gets at the central square.
const MAX_HUB_WAYPOINTS: usize = 4;
/// Inspection waypoints lie at most this far (Chebyshev) from the central square.
const HUB_RING: usize = 5;
/// Score cost of an inspection waypoint half a turn away from the route's sector, in
/// central-square cells: it keeps each UAV on its own side of the square.
const TURN_COST: f64 = 6.0;
/// Least Chebyshev distance between two inspection waypoints of a route: it looks at the
/// square from different sides rather than from a cluster of neighbouring cells.
const LOOKOUT_GAP: usize = 3;

/// The central square: first row and column, side.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Hub {
    pub top: usize,
    pub left: usize,
    pub side: usize,
}

impl Hub {
    /// The central square of a `size` x `size` grid: 3x3 under 24 cells a side, else 5x5.
    pub fn of(size: usize) -> Hub {
        let side = if size < 24 { 3 } else { 5 };
        Hub { top: (size - side) / 2, left: (size - side) / 2, side }
    }

    pub fn contains(&self, (row, col): (usize, usize)) -> bool {
        (self.top..self.top + self.side).contains(&row)
            && (self.left..self.left + self.side).contains(&col)
    }

    /// Chebyshev distance from the square (0 inside).
    fn distance(&self, (row, col): (usize, usize)) -> usize {
        let gap = |x: usize, lo: usize, hi: usize| lo.saturating_sub(x).max(x.saturating_sub(hi));
        let bottom = self.top + self.side - 1;
        let right = self.left + self.side - 1;
        gap(row, self.top, bottom).max(gap(col, self.left, right))
    }

    fn cells(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        (self.top..self.top + self.side)
            .flat_map(move |r| (self.left..self.left + self.side).map(move |c| (r, c)))
    }
}

/// The routes and the central square.
#[derive(Debug, Clone)]
pub(super) struct Layout {
    pub hub: Hub,
    pub routes: Vec<Vec<(usize, usize)>>,
}

/// Continuous coordinates over the grid: the centre and the rim square around it.
struct Frame {
    size: usize,
    centre: f64,
    /// Half the side of the rim square (cell centres 1 and size - 2).
    half: f64,
}

type Point = (f64, f64);

impl Frame {
    /// The rim point at fraction `f` of a clockwise turn from the north-west corner.
    fn rim(&self, f: f64) -> Point {
        let t = (f - f.floor()) * 8.0;
        // Unit square coordinates (row, col) in [-1, 1]: top, right, bottom, left edges.
        let (r, c) = if t < 2.0 {
            (-1.0, t - 1.0)
        } else if t < 4.0 {
            (t - 3.0, 1.0)
        } else if t < 6.0 {
            (1.0, 5.0 - t)
        } else {
            (7.0 - t, -1.0)
        };
        (self.centre + self.half * r, self.centre + self.half * c)
    }

    /// The point a fraction `rho` of the way from the centre to `rim(f)`.
    fn point(&self, f: f64, rho: f64) -> Point {
        let (r, c) = self.rim(f);
        (self.centre + rho * (r - self.centre), self.centre + rho * (c - self.centre))
    }

    /// The turn fraction of the direction from the centre to `cell` (inverse of `rim`).
    fn fraction(&self, (row, col): (usize, usize)) -> f64 {
        let (dr, dc) = (row as f64 - self.centre, col as f64 - self.centre);
        let m = dr.abs().max(dc.abs());
        if m == 0.0 {
            return 0.0;
        }
        let (r, c) = (dr / m, dc / m);
        let t = if r == -1.0 && c < 1.0 {
            c + 1.0
        } else if c == 1.0 && r < 1.0 {
            r + 3.0
        } else if r == 1.0 && c > -1.0 {
            5.0 - c
        } else {
            7.0 - r
        };
        t / 8.0
    }

    /// The grid cell nearest `point`, moved by `jitter` and kept on the grid.
    fn cell(&self, (r, c): Point, jitter: (i64, i64)) -> (usize, usize) {
        let max = self.size as i64 - 1;
        let clamp = |x: f64, j: i64| (x.round() as i64 + j).clamp(0, max) as usize;
        (clamp(r, jitter.0), clamp(c, jitter.1))
    }
}

/// Distance between two turn fractions, in [0, 0.5].
fn turn_distance(a: f64, b: f64) -> f64 {
    let d = (a - b).abs();
    let d = d - d.floor();
    d.min(1.0 - d)
}

fn length(a: Point, b: Point) -> f64 {
    ((a.0 - b.0) * (a.0 - b.0) + (a.1 - b.1) * (a.1 - b.1)).sqrt()
}

/// The point at arc length `at` along `line`.
fn along(line: &[Point], mut at: f64) -> Point {
    for pair in line.windows(2) {
        let l = length(pair[0], pair[1]);
        if at <= l && l > 0.0 {
            let t = at / l;
            return (
                pair[0].0 + t * (pair[1].0 - pair[0].0),
                pair[0].1 + t * (pair[1].1 - pair[0].1),
            );
        }
        at -= l;
    }
    line.last().copied().unwrap_or((0.0, 0.0))
}

/// A cell from which the high camera sees part of the central square.
struct Lookout {
    cell: (usize, usize),
    /// Bit i set when the i-th cell of the square (row-major) is seen from some heading.
    sees: u32,
    fraction: f64,
}

impl Layout {
    /// Lays out `uavs` routes on a `size` x `size` grid, drawing from `rng`.
    pub fn new(size: usize, uavs: usize, rng: &mut Xoshiro256PlusPlus) -> Result<Layout, String> {
        let hub = Hub::of(size);
        let centre = (size as f64 - 1.0) / 2.0;
        let frame = Frame { size, centre, half: centre - 1.0 };
        let lookouts = lookouts(&frame, hub);
        let mut routes = Vec::with_capacity(uavs);
        for uav in 0..uavs {
            let route = route(&frame, hub, &lookouts, uav, uavs, rng);
            if route.len() < MIN_WAYPOINTS {
                return Err(format!(
                    "the {size}x{size} grid leaves UAV{} only {} distinct waypoints, expected \
                     at least {MIN_WAYPOINTS}: use a larger size",
                    uav + 1,
                    route.len()
                ));
            }
            routes.push(route);
        }
        Ok(Layout { hub, routes })
    }
}

/// Every cell near the central square from which the high camera sees part of it.
fn lookouts(frame: &Frame, hub: Hub) -> Vec<Lookout> {
    let mut found = Vec::new();
    for row in 0..frame.size {
        for col in 0..frame.size {
            let cell = (row, col);
            if !(1..=HUB_RING).contains(&hub.distance(cell)) {
                continue;
            }
            let sees = hub.cells().enumerate().fold(0u32, |mask, (i, q)| {
                let seen = Heading::ALL.iter().any(|&h| in_footprint(cell, Height::High, h, q));
                if seen {
                    mask | (1 << i)
                } else {
                    mask
                }
            });
            if sees != 0 {
                found.push(Lookout { cell, sees, fraction: frame.fraction(cell) });
            }
        }
    }
    found
}

/// UAV `uav`'s route: its patrol of sector `uav` of `uavs`, then its inspection of the
/// central square; waypoint 1 is where the patrol meets the rim.
fn route(
    frame: &Frame,
    hub: Hub,
    lookouts: &[Lookout],
    uav: usize,
    uavs: usize,
    rng: &mut Xoshiro256PlusPlus,
) -> Vec<(usize, usize)> {
    let width = 1.0 / uavs as f64;
    let start = uav as f64 * width;
    let middle = start + width / 2.0;
    let inspect = inspection(hub, lookouts, middle, rng);
    // The sides of the wedge, a quarter of the sector (at most 3 cells of rim) inside it.
    let margin = (width / 4.0).min(3.0 / (8.0 * frame.half));
    let (a, b) = (start + margin, start + width - margin);
    // The patrol leaves the central square's ring when the grid is large enough for it.
    let inner = ((hub.side as f64 / 2.0 + 3.5) / frame.half).min(1.0);
    let mut line = Vec::new();
    if inner < 0.8 {
        line.push(frame.point(a, inner));
    }
    let rim_from = line.len();
    line.push(frame.rim(a));
    for corner in 1..4 {
        let f = corner as f64 / 4.0;
        if a < f && f < b {
            line.push(frame.rim(f));
        }
    }
    line.push(frame.rim(b));
    if inner < 0.8 {
        line.push(frame.point(b, inner));
    }
    let total: f64 = line.windows(2).map(|p| length(p[0], p[1])).sum();
    let lo = MIN_WAYPOINTS.saturating_sub(inspect.len()).max(2);
    let hi = MAX_WAYPOINTS - inspect.len();
    let n = ((total / SPACING).round() as usize).clamp(lo, hi);
    // Where the rim starts, as a fraction of the patrol.
    let leg: f64 = line[..=rim_from].windows(2).map(|p| length(p[0], p[1])).sum();
    let leg = leg / total.max(1e-9);
    // On a small grid two waypoints may fall on one cell: sample more densely until the
    // route has enough distinct ones.
    let mut cells = Vec::new();
    for n in n..=hi.max(n) {
        // From the rim round to the inner end of the patrol, the inspection, then the
        // waypoints before the rim (the way out).
        let (rim_on, way_out) = patrol(frame, hub, &line, total, leg, n, rng);
        cells = rim_on;
        for cell in inspect.iter().chain(&way_out) {
            if !cells.contains(cell) {
                cells.push(*cell);
            }
        }
        if cells.len() >= MIN_WAYPOINTS {
            break;
        }
    }
    cells
}

/// A patrol cut in two: from the start of the rim on, and the waypoints before it.
type Split = (Vec<(usize, usize)>, Vec<(usize, usize)>);

/// `n` waypoints evenly spaced along `line` (of length `total`), each moved by up to one
/// cell; none in the central square, none twice. Split at the one nearest the start of the
/// rim (at fraction `leg` of the line).
fn patrol(
    frame: &Frame,
    hub: Hub,
    line: &[Point],
    total: f64,
    leg: f64,
    n: usize,
    rng: &mut Xoshiro256PlusPlus,
) -> Split {
    let first = (leg * (n - 1) as f64).round() as usize;
    let (mut before, mut after) = (Vec::new(), Vec::with_capacity(MAX_WAYPOINTS));
    for i in 0..n {
        let point = along(line, total * i as f64 / (n - 1) as f64);
        let jitter = (below(rng, 3) as i64 - 1, below(rng, 3) as i64 - 1);
        let options = [frame.cell(point, jitter), frame.cell(point, (0, 0))];
        let fresh =
            |c: &(usize, usize)| !hub.contains(*c) && !before.contains(c) && !after.contains(c);
        if let Some(&cell) = options.iter().find(|c| fresh(c)) {
            if i < first {
                before.push(cell);
            } else {
                after.push(cell);
            }
        }
    }
    (after, before)
}

/// The inspection waypoints of a UAV whose sector is centred on turn fraction `middle`:
/// greedily, the lookout that sees the most cells of the square not yet covered, less the
/// cost of its distance from the sector (plus a little noise so seeds differ), at least
/// [`LOOKOUT_GAP`] from the others, until every cell is covered. Ordered counter-clockwise,
/// from the end of the patrol to its start.
fn inspection(
    hub: Hub,
    lookouts: &[Lookout],
    middle: f64,
    rng: &mut Xoshiro256PlusPlus,
) -> Vec<(usize, usize)> {
    let full = (1u32 << (hub.side * hub.side)) - 1;
    let mut covered = 0;
    let mut chosen: Vec<&Lookout> = Vec::new();
    while covered != full && chosen.len() < MAX_HUB_WAYPOINTS {
        let mut best: Option<(f64, &Lookout)> = None;
        for lookout in lookouts {
            let new = (lookout.sees & !covered).count_ones();
            let apart = chosen.iter().all(|c| {
                c.cell.0.abs_diff(lookout.cell.0).max(c.cell.1.abs_diff(lookout.cell.1))
                    >= LOOKOUT_GAP
            });
            if new == 0 || !apart {
                continue;
            }
            let noise = below(rng, 1024) as f64 / 1024.0;
            let score =
                f64::from(new) - TURN_COST * turn_distance(lookout.fraction, middle) + noise;
            if best.is_none_or(|(s, _)| score > s) {
                best = Some((score, lookout));
            }
        }
        let Some((_, lookout)) = best else { break };
        covered |= lookout.sees;
        chosen.push(lookout);
    }
    // Counter-clockwise round the square, from the cut opposite the sector: the patrol comes
    // back in at the sector's clockwise side and leaves from its other side.
    let key = |l: &&Lookout| {
        let d = middle + 0.5 - l.fraction;
        d - d.floor()
    };
    chosen.sort_by(|x, y| key(x).total_cmp(&key(y)));
    chosen.into_iter().map(|l| l.cell).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// Every route has 4..=12 distinct waypoints, none in the central square, and sees
    /// every cell of the square from some high pose, whatever the grid, the number of UAVs
    /// and the seed: what makes `cover=all` possible. (Checked once for 300 seeds.)
    #[test]
    fn every_route_sees_the_whole_central_square() {
        for size in [10, 11, 12, 17, 23, 24, 25, 31, 51, 64, 100] {
            for uavs in [1, 2, 3, 5, 8, 13, 32, 64] {
                if size < crate::generate::min_size(uavs) {
                    continue;
                }
                for seed in 0..3 {
                    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
                    let layout = Layout::new(size, uavs, &mut rng).expect("layout");
                    let hub = layout.hub;
                    for (uav, route) in layout.routes.iter().enumerate() {
                        let at = format!("size {size}, {uavs} UAVs, seed {seed}: UAV{}", uav + 1);
                        assert!((MIN_WAYPOINTS..=MAX_WAYPOINTS).contains(&route.len()), "{at}");
                        for (i, &p) in route.iter().enumerate() {
                            assert!(!hub.contains(p) && !route[..i].contains(&p), "{at}");
                        }
                        for q in hub.cells() {
                            let seen = route.iter().any(|&p| {
                                Heading::ALL.iter().any(|&h| in_footprint(p, Height::High, h, q))
                            });
                            assert!(seen, "{at} misses {q:?}");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn fractions_invert_the_rim() {
        let frame = Frame { size: 20, centre: 9.5, half: 8.5 };
        for i in 0..64 {
            let f = i as f64 / 64.0;
            let (r, c) = frame.rim(f);
            let back = frame.fraction((r.round() as usize, c.round() as usize));
            assert!(turn_distance(back, f) < 0.02, "{f} -> ({r}, {c}) -> {back}");
        }
    }
}
