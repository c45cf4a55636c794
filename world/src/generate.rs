//! Generated scenarios: a valid map for any number of UAVs from a short spec.
//!
//! The thesis stops at two UAVs on 10x10. `gen:size=S,uavs=N,targets=T,occlusion=P,
//! cover=C,seed=X` describes a map for N UAVs (1..=64); every key is optional:
//!
//! | key | meaning | default | range |
//! |---|---|---|---|
//! | `uavs` | routes (UAVs) | 2 | 1..=64 |
//! | `size` | grid side (S x S) | `10 + 2*uavs`, at most 64 | 10..=256, >= 40 cells per UAV |
//! | `targets` | candidate target cells | `max(2, uavs/2)` | 1..=64 |
//! | `occlusion` | density of `X` cells | 0.15 | 0..=0.6 |
//! | `cover` | routes that must see each target | 1 | 1..=uavs, or `all` |
//! | `seed` | the generator's seed | 1 | u64 |
//!
//! The layout (`generate/layout.rs`): UAV k patrols sector k of the grid (a wedge from the centre to
//! one N-th of the rim, clockwise from the north-west corner) and inspects a central square
//! from its own side; routes have 4..=12 waypoints about 3 cells apart, start `wp1 low N`
//! where the patrol meets the rim. `X` cells are then drawn with probability `occlusion`
//! on every cell but the waypoints and the central square. Targets are drawn among the
//! free cells that are not waypoints and are seen by at least `cover` routes, each with
//! weight the number of routes that see it (cells many UAVs watch, where communication
//! helps, are favoured), at least two cells apart when possible. If too few cells qualify
//! the occlusion is drawn again, a bounded number of times, then the spec is refused.
//!
//! Every fact (for each route and target, exactly the poses that see it, or `none`) is
//! written into the map, which is then rendered with [`MapFile::to_text`] and loaded back
//! through [`Scenario::from_text`]: a generated scenario passed the same checks as a file.
//!
//! A UAV's episode ends only when it sees the target itself (SPEC 2), so a target that some
//! route never sees cuts every episode that draws it at the tick cap. `cover=all` rules
//! that out; [`default_generated_spec`], what the supervisor runs for N > 2, uses it.
//!
//! Same spec, same bytes on every machine: one `Xoshiro256PlusPlus` seeded from `seed`
//! (independent streams for routes, occlusion and targets), integer sampling only, and
//! geometry with `+ - * /`, `sqrt` and rounding, which IEEE 754 fixes exactly.

mod layout;
mod spec;

use flockstep_proto::{Heading, Height, Pose};
use rand::{RngCore, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

use crate::error::WorldError;
use crate::map::{Cell, Expect, MapFile};
use crate::scenario::Scenario;
use crate::visibility;
use layout::Layout;
use spec::spec_error;
pub use spec::{
    default_size, default_targets, min_size, Cover, GenSpec, DEFAULT_OCCLUSION, DEFAULT_SEED,
    DEFAULT_UAVS, MAX_OCCLUSION, MAX_SIZE, MIN_SIZE, PREFIX,
};

/// Times the occlusion is drawn again when too few cells qualify as targets.
const ATTEMPTS: usize = 8;
/// Most targets [`default_generated_spec`] asks for.
const DEFAULT_SPEC_MAX_TARGETS: usize = 8;

/// The spec the supervisor runs by default for `uavs` UAVs when no map is given (N > 2;
/// for 1 and 2 it runs the thesis's s2 and s3): `gen:uavs=N,targets=T,cover=all` with
/// `T = min(max(2, N/2), 8)` and the other keys at their defaults (size `10 + 2N` capped
/// at 64, occlusion 0.15, seed 1).
///
/// Why `cover=all`: a UAV ends its episode only when it sees the target itself, so every
/// route must see every target, or the episodes drawing that target all run to the tick
/// cap. Every UAV sees the central square, so the targets lie there and near it, each
/// seen from different poses of different routes; at most 8 of them keep the square's
/// cells apart and each UAV's search short enough to learn.
pub fn default_generated_spec(uavs: usize) -> String {
    let targets = default_targets(uavs).min(DEFAULT_SPEC_MAX_TARGETS);
    format!("{PREFIX}uavs={uavs},targets={targets},cover=all")
}

/// The map text of `spec` (`gen:...`), verified by loading it: what
/// `supervisor generate SPEC --out FILE` writes.
pub fn generate_text(spec: &str) -> Result<String, WorldError> {
    generated(spec).map(|(text, _)| text)
}

/// The scenario of `spec` (`gen:...`), loaded from its map text like a file; errors name
/// `spec`.
pub fn generate(spec: &str) -> Result<Scenario, WorldError> {
    generated(spec).map(|(_, scenario)| scenario)
}

/// The map of a parsed spec, with every fact; its `name:` is the canonical spec.
pub fn generate_map(spec: &GenSpec) -> Result<MapFile, WorldError> {
    let name = spec.to_string();
    let err = |problem: String| spec_error(&name, problem);
    let mut routes_rng = Xoshiro256PlusPlus::seed_from_u64(spec.seed);
    let mut occlusion_rng = routes_rng.clone();
    occlusion_rng.jump();
    let mut targets_rng = occlusion_rng.clone();
    targets_rng.jump();

    let layout = Layout::new(spec.size, spec.uavs, &mut routes_rng).map_err(err)?;
    let mut map = MapFile {
        name: name.clone(),
        rows: spec.size,
        cols: spec.size,
        cells: Vec::new(),
        targets: Vec::new(),
        // Known once the text is written; the map is always loaded back from its text.
        target_at: Vec::new(),
        routes: layout.routes.clone(),
        start: Pose::new(0, Height::Low, Heading::N),
        expects: Vec::new(),
    };
    let mut most = 0;
    for _ in 0..ATTEMPTS {
        map.cells = occlusion(spec, &layout, &mut occlusion_rng);
        let watchers = watchers(&map);
        match choose_targets(spec, &map, &watchers, &mut targets_rng) {
            Ok(targets) => {
                map.targets = targets;
                map.expects = facts(&map);
                return Ok(map);
            }
            Err(qualifying) => most = most.max(qualifying),
        }
    }
    let routes = match spec.cover {
        Cover::All => "all routes".to_string(),
        Cover::Routes(1) => "some route".to_string(),
        Cover::Routes(k) => format!("at least {k} routes"),
    };
    Err(err(format!(
        "cannot place {} targets seen by {routes}: at most {most} cells qualify (free, not a \
         waypoint, seen by enough routes) in {ATTEMPTS} draws of the occlusion; ask for fewer \
         targets, a lower cover, less occlusion or a larger size",
        spec.targets
    )))
}

/// Generates, renders and loads `spec`: the text (a header, then the map) and its scenario.
fn generated(spec: &str) -> Result<(String, Scenario), WorldError> {
    let parsed = GenSpec::parse(spec)?;
    // Name the spec as the user wrote it, as the parse errors do.
    let map = generate_map(&parsed).map_err(|e| match e {
        WorldError::Spec { problem, .. } => spec_error(spec, problem),
        other => other,
    })?;
    let text = format!("{}{}", header(&parsed, &map), map.to_text());
    let scenario = Scenario::from_text(spec, &text)?;
    Ok((text, scenario))
}

/// Comment lines saying where the map comes from and how it is laid out.
fn header(spec: &GenSpec, map: &MapFile) -> String {
    let hub = layout::Hub::of(spec.size);
    let (first, last) = (hub.top, hub.top + hub.side - 1);
    let mut watched = vec![0usize; map.targets.len()];
    for fact in map.expects.iter().filter(|f| !f.poses.is_empty()) {
        watched[fact.target] += 1;
    }
    let mean = watched.iter().sum::<usize>() as f64 / watched.len().max(1) as f64;
    let least = watched.iter().min().copied().unwrap_or(0);
    let most = watched.iter().max().copied().unwrap_or(0);
    format!(
        "# Generated by flockstep from `{spec}`:\n\
         # the same spec gives the same bytes on every machine.\n\
         # UAV k patrols sector k of the grid (wedges from the centre to the rim, clockwise\n\
         # from the north-west corner) and inspects the central square (rows and columns\n\
         # {first}..{last}) from its side. Each target is seen by {least} to {most} routes \
         ({mean:.1} on average).\n"
    )
}

/// A number in `0..n` from `rng` (multiply-shift: the same on every platform).
pub(crate) fn below(rng: &mut Xoshiro256PlusPlus, n: u64) -> u64 {
    ((u128::from(rng.next_u64()) * u128::from(n)) >> 64) as u64
}

/// The grid: each cell an `X` with probability `occlusion`, except the waypoints and the
/// central square.
fn occlusion(spec: &GenSpec, layout: &Layout, rng: &mut Xoshiro256PlusPlus) -> Vec<Cell> {
    // P * 2^64, exact for the decimals a spec can hold; 0.6 keeps it below 2^64.
    let threshold = (spec.occlusion * 18_446_744_073_709_551_616.0) as u64;
    let mut cells = Vec::with_capacity(spec.size * spec.size);
    for row in 0..spec.size {
        for col in 0..spec.size {
            let cell = (row, col);
            // Drawn for every cell so that one cell's exclusion does not shift the others.
            let x = rng.next_u64() < threshold;
            let kept = layout.hub.contains(cell) || layout.routes.iter().any(|r| r.contains(&cell));
            cells.push(if x && !kept { Cell::Occlusion } else { Cell::Free });
        }
    }
    cells
}

/// Per cell (row-major), bit u set when some pose of route u sees it.
fn watchers(map: &MapFile) -> Vec<u64> {
    let mut seen = vec![0u64; map.rows * map.cols];
    for (uav, route) in map.routes.iter().enumerate() {
        for &cell in route {
            for height in Height::ALL {
                for heading in Heading::ALL {
                    for (r, c) in visibility::visible_cells(map, cell, height, heading) {
                        seen[r * map.cols + c] |= 1 << uav;
                    }
                }
            }
        }
    }
    seen
}

/// `spec.targets` cells seen by enough routes, drawn with weight the number of routes that
/// see them, two apart (Chebyshev) while possible; sorted row-major. `Err` carries how many
/// cells qualify.
fn choose_targets(
    spec: &GenSpec,
    map: &MapFile,
    watchers: &[u64],
    rng: &mut Xoshiro256PlusPlus,
) -> Result<Vec<(usize, usize)>, usize> {
    let needed = spec.cover_routes() as u32;
    let mut candidates: Vec<((usize, usize), u64)> = Vec::new();
    for (i, &mask) in watchers.iter().enumerate() {
        let cell = (i / map.cols, i % map.cols);
        let free = map.cells[i] == Cell::Free;
        let waypoint = map.routes.iter().any(|r| r.contains(&cell));
        if free && !waypoint && mask.count_ones() >= needed {
            candidates.push((cell, u64::from(mask.count_ones())));
        }
    }
    if candidates.len() < spec.targets {
        return Err(candidates.len());
    }
    let mut chosen: Vec<(usize, usize)> = Vec::with_capacity(spec.targets);
    // First apart from each other; then, if that runs out, anywhere left.
    for gap in [2, 1] {
        let mut pool: Vec<_> = candidates
            .iter()
            .copied()
            .filter(|&(cell, _)| chosen.iter().all(|&t| chebyshev(t, cell) >= gap))
            .collect();
        while chosen.len() < spec.targets && !pool.is_empty() {
            let total: u64 = pool.iter().map(|c| c.1).sum();
            let mut pick = below(rng, total);
            let index = pool
                .iter()
                .position(|c| {
                    let hit = pick < c.1;
                    pick -= c.1.min(pick);
                    hit
                })
                .unwrap_or(pool.len() - 1);
            let (cell, _) = pool.swap_remove(index);
            chosen.push(cell);
            pool.retain(|&(other, _)| chebyshev(other, cell) >= gap);
        }
    }
    chosen.sort_unstable();
    Ok(chosen)
}

fn chebyshev(a: (usize, usize), b: (usize, usize)) -> usize {
    a.0.abs_diff(b.0).max(a.1.abs_diff(b.1))
}

/// For every route and target, the poses that see the target (empty: `none`).
fn facts(map: &MapFile) -> Vec<Expect> {
    let mut facts = Vec::with_capacity(map.routes.len() * map.targets.len());
    for (uav, route) in map.routes.iter().enumerate() {
        for (target, &cell) in map.targets.iter().enumerate() {
            let mut poses = Vec::new();
            // Waypoint, then height (low first), then heading: the order facts are kept in.
            for (wp, &at) in route.iter().enumerate() {
                for height in Height::ALL {
                    for heading in Heading::ALL {
                        if visibility::is_visible(map, at, height, heading, cell) {
                            poses.push(Pose::new(wp, height, heading));
                        }
                    }
                }
            }
            facts.push(Expect { uav, target, poses, line: 0 });
        }
    }
    facts
}
