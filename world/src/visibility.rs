//! The camera model of SPEC section 2: which cells a pose sees.
//!
//! A pose at cell p, height z, heading h sees cell q when q lies in the footprint of
//! (z, h), is on the grid, is not an `X`, and (at low height only) no `X` lies on the
//! line of sight. The footprint is a wedge ahead of the UAV: with f the forward distance
//! and l the absolute lateral offset of q, low covers 1 <= f <= 3 and high 3 <= f <= 6,
//! both with l <= f/2 (integer division). The line of sight is the supercover line between
//! the two cell centres, computed with integers only so that a segment passing exactly
//! through a cell corner is recognised as such: both cells beside that corner count.
//! The thesis maps depend on this rule (a Bresenham line breaks some of their facts).

use flockstep_proto::{Heading, Height};

use crate::map::MapFile;

/// Forward distance range (inclusive) of the footprint at `height`.
fn depth(height: Height) -> (i64, i64) {
    match height {
        Height::Low => (1, 3),
        Height::High => (3, 6),
    }
}

/// (forward, right) unit steps of `heading` as (d_row, d_col) pairs; right is clockwise.
fn axes(heading: Heading) -> ((i64, i64), (i64, i64)) {
    let (fr, fc) = heading.forward();
    let (fr, fc) = (i64::from(fr), i64::from(fc));
    ((fr, fc), (fc, -fr))
}

fn signed(cell: (usize, usize)) -> (i64, i64) {
    // Grid sides are bounded by the map text, far below i64::MAX.
    (cell.0 as i64, cell.1 as i64)
}

/// Whether `q` lies in the footprint of a camera at `p` (geometry only: no grid, no `X`).
pub fn in_footprint(
    p: (usize, usize),
    height: Height,
    heading: Heading,
    q: (usize, usize),
) -> bool {
    let ((p_r, p_c), (q_r, q_c)) = (signed(p), signed(q));
    let (dr, dc) = (q_r - p_r, q_c - p_c);
    let ((fr, fc), (rr, rc)) = axes(heading);
    let forward = dr * fr + dc * fc;
    let lateral = (dr * rr + dc * rc).abs();
    let (near, far) = depth(height);
    (near..=far).contains(&forward) && lateral <= forward / 2
}

/// Calls `visit` on every cell the segment between the centres of `p` and `q` touches,
/// `p` and `q` excluded, in order from `p`; stops early and returns false as soon as
/// `visit` does.
fn walk_between(p: (i64, i64), q: (i64, i64), mut visit: impl FnMut(i64, i64) -> bool) -> bool {
    let (dr, dc) = (q.0 - p.0, q.1 - p.1);
    let (n_r, n_c) = (dr.abs(), dc.abs());
    let (s_r, s_c) = (dr.signum(), dc.signum());
    let (mut r, mut c) = p;
    let (mut i_r, mut i_c) = (0, 0);
    while i_r < n_r || i_c < n_c {
        // The segment next crosses a row boundary at (1 + 2 i_r) / (2 n_r) of its length and
        // a column boundary at (1 + 2 i_c) / (2 n_c); compare them cross-multiplied, exactly.
        let decision = (1 + 2 * i_c) * n_r - (1 + 2 * i_r) * n_c;
        if decision == 0 {
            // Exactly through a corner: the two cells beside it are touched too.
            if !visit(r + s_r, c) || !visit(r, c + s_c) {
                return false;
            }
            (r, c, i_r, i_c) = (r + s_r, c + s_c, i_r + 1, i_c + 1);
        } else if decision < 0 {
            (c, i_c) = (c + s_c, i_c + 1);
        } else {
            (r, i_r) = (r + s_r, i_r + 1);
        }
        if (r, c) != q && !visit(r, c) {
            return false;
        }
    }
    true
}

/// The cells strictly between `p` and `q` on the supercover line, from `p` towards `q`.
pub fn supercover_between(p: (usize, usize), q: (usize, usize)) -> Vec<(usize, usize)> {
    let mut cells = Vec::new();
    walk_between(signed(p), signed(q), |r, c| {
        // The walk stays inside the bounding box of p and q, so the cells are never negative.
        cells.push((r as usize, c as usize));
        true
    });
    cells
}

/// Whether a camera at `p` (height, heading) sees cell `q` of `map`.
pub fn is_visible(
    map: &MapFile,
    p: (usize, usize),
    height: Height,
    heading: Heading,
    q: (usize, usize),
) -> bool {
    if !in_footprint(p, height, heading, q)
        || map.cell(q.0, q.1).is_none()
        || map.is_occluded(q.0, q.1)
    {
        return false;
    }
    match height {
        Height::High => true,
        Height::Low => {
            walk_between(signed(p), signed(q), |r, c| !map.is_occluded(r as usize, c as usize))
        }
    }
}

/// Every cell of `map` a camera at `p` (height, heading) sees, in row-major order.
pub fn visible_cells(
    map: &MapFile,
    p: (usize, usize),
    height: Height,
    heading: Heading,
) -> Vec<(usize, usize)> {
    let (p_r, p_c) = signed(p);
    let ((fr, fc), (rr, rc)) = axes(heading);
    let (near, far) = depth(height);
    let mut cells = Vec::new();
    for forward in near..=far {
        for lateral in -(forward / 2)..=forward / 2 {
            let (r, c) = (p_r + forward * fr + lateral * rr, p_c + forward * fc + lateral * rc);
            let (Ok(r), Ok(c)) = (usize::try_from(r), usize::try_from(c)) else { continue };
            if is_visible(map, p, height, heading, (r, c)) {
                cells.push((r, c));
            }
        }
    }
    cells.sort_unstable();
    cells
}
