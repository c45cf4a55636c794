//! The camera model of SPEC section 2: footprints, occlusion, the supercover corner rule.

use std::collections::BTreeSet;

use flockstep_proto::{Heading, Height};
use flockstep_world::visibility::{in_footprint, is_visible, supercover_between, visible_cells};
use flockstep_world::{parse_map, MapFile};
use proptest::prelude::*;

/// A 13x13 map, free but for `xs`, with one target (maps need one) in a corner.
fn open_map(xs: &[(usize, usize)]) -> MapFile {
    let rows: Vec<String> = (0..13)
        .map(|r| {
            let cells: Vec<&str> = (0..13)
                .map(|c| match (r, c) {
                    (12, 12) => "T1",
                    _ if xs.contains(&(r, c)) => "X",
                    _ => ".",
                })
                .collect();
            cells.join(" ")
        })
        .collect();
    let text = format!(
        "name: open\nsize: 13 13\nstart: wp1 low N\ngrid:\n{}\nroute UAV1: 6,6\n",
        rows.join("\n")
    );
    parse_map("open.map", &text).expect("the open map parses")
}

fn set(cells: &[(usize, usize)]) -> BTreeSet<(usize, usize)> {
    cells.iter().copied().collect()
}

/// Offsets (forward, lateral to the right) turned into cells around (6, 6).
fn around(heading: Heading, offsets: &[(i64, i64)]) -> BTreeSet<(usize, usize)> {
    let (fr, fc) = heading.forward();
    let (fr, fc) = (i64::from(fr), i64::from(fc));
    offsets
        .iter()
        .map(|&(f, l)| ((6 + f * fr + l * fc) as usize, (6 + f * fc - l * fr) as usize))
        .collect()
}

const LOW: [(i64, i64); 7] = [(1, 0), (2, -1), (2, 0), (2, 1), (3, -1), (3, 0), (3, 1)];

#[test]
fn low_footprint_is_a_seven_cell_wedge_in_every_heading() {
    let map = open_map(&[]);
    let north = set(&[(5, 6), (4, 5), (4, 6), (4, 7), (3, 5), (3, 6), (3, 7)]);
    assert_eq!(set(&visible_cells(&map, (6, 6), Height::Low, Heading::N)), north);
    let east = set(&[(6, 7), (5, 8), (6, 8), (7, 8), (5, 9), (6, 9), (7, 9)]);
    assert_eq!(set(&visible_cells(&map, (6, 6), Height::Low, Heading::E)), east);
    let south = set(&[(7, 6), (8, 5), (8, 6), (8, 7), (9, 5), (9, 6), (9, 7)]);
    assert_eq!(set(&visible_cells(&map, (6, 6), Height::Low, Heading::S)), south);
    let west = set(&[(6, 5), (5, 4), (6, 4), (7, 4), (5, 3), (6, 3), (7, 3)]);
    assert_eq!(set(&visible_cells(&map, (6, 6), Height::Low, Heading::W)), west);
    for heading in Heading::ALL {
        assert_eq!(set(&visible_cells(&map, (6, 6), Height::Low, heading)), around(heading, &LOW));
    }
}

#[test]
fn high_footprint_is_a_twenty_cell_wedge_from_three_to_six_ahead() {
    let map = open_map(&[]);
    let mut offsets = Vec::new();
    for (f, half) in [(3, 1), (4, 2), (5, 2), (6, 3)] {
        offsets.extend((-half..=half).map(|l| (f, l)));
    }
    assert_eq!(offsets.len(), 20);
    for heading in Heading::ALL {
        let cells = visible_cells(&map, (6, 6), Height::High, heading);
        assert_eq!(set(&cells), around(heading, &offsets), "{heading:?}");
    }
    let north = set(&visible_cells(&map, (6, 6), Height::High, Heading::N));
    assert!(north.contains(&(0, 3)) && north.contains(&(0, 9)) && north.contains(&(3, 6)));
    assert!(!north.contains(&(4, 6)) && !north.contains(&(0, 2)));
}

#[test]
fn the_footprint_is_clipped_by_the_grid_edge() {
    let map = open_map(&[]);
    assert!(visible_cells(&map, (0, 0), Height::Low, Heading::N).is_empty());
    let east = set(&visible_cells(&map, (0, 0), Height::Low, Heading::E));
    assert_eq!(east, set(&[(0, 1), (0, 2), (1, 2), (0, 3), (1, 3)]));
    assert!(!in_footprint((0, 0), Height::High, Heading::E, (0, 2)));
    assert!(in_footprint((0, 0), Height::High, Heading::E, (3, 6)));
}

#[test]
fn an_occlusion_is_never_visible() {
    let map = open_map(&[(5, 6), (1, 6)]);
    assert!(!is_visible(&map, (6, 6), Height::Low, Heading::N, (5, 6)));
    assert!(!is_visible(&map, (6, 6), Height::High, Heading::N, (1, 6)));
}

#[test]
fn an_occlusion_blocks_at_low_height_only() {
    // An X two cells ahead hides what is behind it at low height, including (3, 5) and
    // (3, 7), whose lines pass through a corner of the X ...
    let map = open_map(&[(4, 6), (2, 6)]);
    let low = set(&visible_cells(&map, (6, 6), Height::Low, Heading::N));
    assert_eq!(low, set(&[(5, 6), (4, 5), (4, 7)]));
    // ... but from high the camera looks over buildings: only the X cells are missing.
    let high = set(&visible_cells(&map, (6, 6), Height::High, Heading::N));
    assert_eq!(high.len(), 19);
    assert!(!high.contains(&(2, 6)) && high.contains(&(3, 6)) && high.contains(&(0, 6)));
}

#[test]
fn the_supercover_line_lists_every_cell_the_segment_touches() {
    // Straight: the cells in between.
    assert_eq!(supercover_between((6, 6), (3, 6)), vec![(5, 6), (4, 6)]);
    // Through the middle of an edge: one cell per crossing.
    assert_eq!(supercover_between((5, 5), (3, 6)), vec![(4, 5), (4, 6)]);
    // Through a corner at (4, 6): both cells beside it, (3, 5) and (4, 6), are touched.
    assert_eq!(supercover_between((5, 5), (2, 6)), vec![(4, 5), (3, 5), (4, 6), (3, 6)]);
    // Neighbours have nothing in between.
    assert!(supercover_between((5, 5), (4, 5)).is_empty());
}

#[test]
fn a_line_through_a_corner_is_blocked_by_either_cell_beside_it() {
    let target = (2, 6);
    for x in [(3, 5), (4, 6), (4, 5), (3, 6)] {
        let map = open_map(&[x]);
        assert!(
            !is_visible(&map, (5, 5), Height::Low, Heading::N, target),
            "X at {x:?} must block"
        );
    }
    // An X next to the line but not touched by it does not block.
    for x in [(2, 5), (4, 4), (3, 7)] {
        let map = open_map(&[x]);
        assert!(
            is_visible(&map, (5, 5), Height::Low, Heading::N, target),
            "X at {x:?} must not block"
        );
    }
}

fn gcd(a: usize, b: usize) -> usize {
    if b == 0 {
        a
    } else {
        gcd(b, a % b)
    }
}

proptest! {
    #[test]
    fn the_supercover_line_is_symmetric_and_stays_in_the_box(
        a in (0usize..20, 0usize..20),
        b in (0usize..20, 0usize..20),
    ) {
        let there = supercover_between(a, b);
        prop_assert_eq!(set(&there), set(&supercover_between(b, a)));
        for &(r, c) in &there {
            prop_assert!(r >= a.0.min(b.0) && r <= a.0.max(b.0));
            prop_assert!(c >= a.1.min(b.1) && c <= a.1.max(b.1));
            prop_assert!((r, c) != a && (r, c) != b);
        }
        // Each row or column boundary crossed enters one cell (the last one is b); a corner
        // crosses two boundaries at once and adds the two cells beside it. The segment meets
        // corners when dr/g and dc/g are both odd (g = gcd), g times.
        let (dr, dc) = (a.0.abs_diff(b.0), a.1.abs_diff(b.1));
        let g = gcd(dr, dc);
        let corners = if g > 0 && (dr / g) % 2 == 1 && (dc / g) % 2 == 1 { g } else { 0 };
        prop_assert_eq!(there.len(), (dr + dc).saturating_sub(1) + corners);
    }
}
