//! The `gen:` scenario spec: its grammar, defaults and limits.
//!
//! `gen:key=value,key=value,...` with the keys `size`, `uavs`, `targets`, `occlusion`,
//! `cover` and `seed` in any order, each at most once, all optional. A parsed spec is
//! written back in one canonical form (every key, fixed order), which is the generated
//! map's `name:`, so a map file says exactly how to make it again.

use std::fmt;

use flockstep_proto::limits::{MAX_AGENTS, MAX_TARGETS};

use crate::error::WorldError;

/// What starts a generated-scenario spec.
pub const PREFIX: &str = "gen:";
/// Smallest grid side: a central square, a ring of inspection waypoints and a rim.
pub const MIN_SIZE: usize = 10;
/// Largest grid side (a 256x256 map is about 200 KB of text).
pub const MAX_SIZE: usize = 256;
/// Largest default grid side: `10 + 2 * uavs` grows too fast beyond it.
pub const DEFAULT_SIZE_CAP: usize = 64;
/// Largest occlusion density: beyond it the low camera sees almost nothing.
pub const MAX_OCCLUSION: f64 = 0.6;
/// Default occlusion density.
pub const DEFAULT_OCCLUSION: f64 = 0.15;
/// Default UAV count, as the supervisor's.
pub const DEFAULT_UAVS: usize = 2;
/// Default seed.
pub const DEFAULT_SEED: u64 = 1;
/// Cells of grid per UAV below which the sectors are too thin for a patrol.
const CELLS_PER_UAV: usize = 40;

/// How many routes must see each target.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cover {
    /// At least this many routes (1..=uavs).
    Routes(usize),
    /// Every route: every UAV can end every episode by itself.
    All,
}

/// A parsed and range-checked `gen:` spec; every field has its final value.
#[derive(Debug, Clone, PartialEq)]
pub struct GenSpec {
    /// Grid side (the grid is `size` x `size`).
    pub size: usize,
    /// Number of routes (UAVs).
    pub uavs: usize,
    /// Number of candidate target cells.
    pub targets: usize,
    /// Probability that an eligible cell is an `X`.
    pub occlusion: f64,
    /// How many routes must see each target.
    pub cover: Cover,
    pub seed: u64,
}

/// The smallest grid side `gen:` accepts for `uavs` UAVs: [`MIN_SIZE`], and at least
/// 40 cells per UAV so that every sector has room for a patrol.
pub fn min_size(uavs: usize) -> usize {
    let cells = uavs.saturating_mul(CELLS_PER_UAV);
    let mut side = MIN_SIZE;
    while side * side < cells {
        side += 1;
    }
    side
}

/// The default grid side: `10 + 2 * uavs`, capped at 64, never below [`min_size`].
pub fn default_size(uavs: usize) -> usize {
    (10 + 2 * uavs).min(DEFAULT_SIZE_CAP).max(min_size(uavs))
}

/// The default number of targets: `max(2, uavs / 2)`.
pub fn default_targets(uavs: usize) -> usize {
    (uavs / 2).max(2)
}

/// A spec error: names the spec as given and the problem.
pub(crate) fn spec_error(spec: &str, problem: impl Into<String>) -> WorldError {
    WorldError::Spec { spec: spec.to_string(), problem: problem.into() }
}

/// The keys, in canonical order, with what each expects (for messages).
const KEYS: [(&str, &str); 6] = [
    ("size", "the grid side, an integer"),
    ("uavs", "the number of UAVs (routes), an integer"),
    ("targets", "the number of candidate target cells, an integer"),
    ("occlusion", "the density of `X` cells, a decimal such as 0.15"),
    ("cover", "the routes that must see each target: an integer or `all`"),
    ("seed", "the generator's seed, an unsigned integer"),
];

/// Values as written, before defaults and ranges.
#[derive(Default)]
struct Given {
    size: Option<usize>,
    uavs: Option<usize>,
    targets: Option<usize>,
    occlusion: Option<f64>,
    cover: Option<Cover>,
    seed: Option<u64>,
}

impl GenSpec {
    /// Whether `spec` asks for a generated scenario (starts with `gen:`).
    pub fn is_gen(spec: &str) -> bool {
        spec.starts_with(PREFIX)
    }

    /// Parses `gen:key=value,...`, fills the defaults and checks the ranges.
    pub fn parse(spec: &str) -> Result<GenSpec, WorldError> {
        let err = |problem: String| spec_error(spec, problem);
        let Some(body) = spec.strip_prefix(PREFIX) else {
            return Err(err(format!("expected a spec starting with `{PREFIX}`")));
        };
        let mut given = Given::default();
        let mut seen: Vec<&str> = Vec::new();
        for item in body.split(',').map(str::trim) {
            if item.is_empty() {
                if body.trim().is_empty() {
                    break;
                }
                return Err(err("empty item: expected `key=value` between commas".into()));
            }
            let Some((key, value)) = item.split_once('=') else {
                return Err(err(format!("`{item}` is not `key=value` (keys: {})", key_list())));
            };
            let (key, value) = (key.trim(), value.trim());
            let Some(&(key, what)) = KEYS.iter().find(|k| k.0 == key) else {
                return Err(err(format!("unknown key `{key}`: expected one of {}", key_list())));
            };
            if seen.contains(&key) {
                return Err(err(format!("`{key}` is given twice")));
            }
            seen.push(key);
            let bad = || err(format!("bad value `{value}` for `{key}`: expected {what}"));
            match key {
                "size" => given.size = Some(integer(value).ok_or_else(bad)?),
                "uavs" => given.uavs = Some(integer(value).ok_or_else(bad)?),
                "targets" => given.targets = Some(integer(value).ok_or_else(bad)?),
                "occlusion" => given.occlusion = Some(decimal(value).ok_or_else(bad)?),
                "cover" => {
                    let cover = match value {
                        "all" => Some(Cover::All),
                        v => integer(v).map(Cover::Routes),
                    };
                    given.cover = Some(cover.ok_or_else(bad)?);
                }
                _ => given.seed = Some(integer(value).ok_or_else(bad)?),
            }
        }
        GenSpec::complete(spec, given)
    }

    /// Fills the defaults and checks every range.
    fn complete(spec: &str, given: Given) -> Result<GenSpec, WorldError> {
        let err = |problem: String| spec_error(spec, problem);
        let uavs = given.uavs.unwrap_or(DEFAULT_UAVS);
        if !(1..=MAX_AGENTS).contains(&uavs) {
            return Err(err(format!("uavs must be in 1..={MAX_AGENTS}, found {uavs}")));
        }
        let size = given.size.unwrap_or_else(|| default_size(uavs));
        if !(MIN_SIZE..=MAX_SIZE).contains(&size) {
            return Err(err(format!("size must be in {MIN_SIZE}..={MAX_SIZE}, found {size}")));
        }
        let least = min_size(uavs);
        if size < least {
            let problem = format!(
                "size {size} is too small for {uavs} UAVs: at least {least} \
                 ({CELLS_PER_UAV} cells per UAV)"
            );
            return Err(err(problem));
        }
        let targets = given.targets.unwrap_or_else(|| default_targets(uavs));
        if !(1..=MAX_TARGETS).contains(&targets) {
            return Err(err(format!("targets must be in 1..={MAX_TARGETS}, found {targets}")));
        }
        let occlusion = given.occlusion.unwrap_or(DEFAULT_OCCLUSION);
        if !(0.0..=MAX_OCCLUSION).contains(&occlusion) {
            let problem = format!("occlusion must be in 0..={MAX_OCCLUSION}, found {occlusion}");
            return Err(err(problem));
        }
        let cover = given.cover.unwrap_or(Cover::Routes(1));
        if let Cover::Routes(k) = cover {
            if !(1..=uavs).contains(&k) {
                let problem =
                    format!("cover must be `all` or in 1..={uavs} (the number of UAVs), found {k}");
                return Err(err(problem));
            }
        }
        let seed = given.seed.unwrap_or(DEFAULT_SEED);
        Ok(GenSpec { size, uavs, targets, occlusion, cover, seed })
    }

    /// The number of routes each target must be seen by.
    pub fn cover_routes(&self) -> usize {
        match self.cover {
            Cover::Routes(k) => k,
            Cover::All => self.uavs,
        }
    }
}

impl fmt::Display for Cover {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Cover::Routes(k) => write!(f, "{k}"),
            Cover::All => write!(f, "all"),
        }
    }
}

impl fmt::Display for GenSpec {
    /// The canonical spec: every key, in a fixed order; it parses back to `self`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let GenSpec { size, uavs, targets, occlusion, cover, seed } = self;
        write!(
            f,
            "{PREFIX}size={size},uavs={uavs},targets={targets},occlusion={occlusion},\
             cover={cover},seed={seed}"
        )
    }
}

fn key_list() -> String {
    let keys: Vec<String> = KEYS.iter().map(|k| format!("`{}`", k.0)).collect();
    keys.join(", ")
}

/// Digits only (no sign), as `str::parse` of an unsigned integer reads them.
fn integer<T: std::str::FromStr>(text: &str) -> Option<T> {
    if text.is_empty() || !text.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    text.parse().ok()
}

/// A plain decimal: digits with at most one `.` (no sign, exponent, `inf` or `nan`).
fn decimal(text: &str) -> Option<f64> {
    let digits = text.bytes().filter(u8::is_ascii_digit).count();
    let dots = text.bytes().filter(|&b| b == b'.').count();
    if digits == 0 || dots > 1 || digits + dots != text.len() {
        return None;
    }
    text.parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_follow_the_uav_count() {
        let spec = GenSpec::parse("gen:").expect("defaults");
        assert_eq!(spec.to_string(), "gen:size=14,uavs=2,targets=2,occlusion=0.15,cover=1,seed=1");
        let spec = GenSpec::parse("gen:uavs=64").expect("64");
        assert_eq!((spec.size, spec.targets), (64, 32));
        assert_eq!(min_size(64), 51);
        assert_eq!(default_size(8), 26);
    }

    #[test]
    fn the_canonical_form_parses_back() {
        let spec = GenSpec::parse("gen: seed=9 , cover=all,occlusion=.5,uavs=3").expect("spec");
        assert_eq!(spec.occlusion, 0.5);
        assert_eq!(GenSpec::parse(&spec.to_string()).expect("again"), spec);
    }

    #[test]
    fn numbers_are_plain() {
        assert_eq!(integer::<usize>("+3"), None);
        assert_eq!(decimal("1e-1"), None);
        assert_eq!(decimal("nan"), None);
        assert_eq!(decimal("."), None);
        assert_eq!(decimal("0.25"), Some(0.25));
    }
}
