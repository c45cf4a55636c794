//! The work of one barrier round without any transport: the world's observation, every
//! agent's `act`, the world's checks and steps, its episode reports. `throughput` measures
//! the product over shared memory, where each agent shares its core with another process;
//! this bench isolates the part that grows with the trials, which decides how far 4 trials
//! per round outrun 1 (`docs/PERFORMANCE.md`, "Where a round goes").
//!
//! `cargo bench --bench round` times a round of s3 (2 UAVs, `flags`) at 1 and 4 trials,
//! after 300 000 rounds of training so that tables and episode lengths are those of a run in
//! progress:
//! - `warm`: rounds back to back, everything in cache (the in-process runner's case);
//! - `cold`: 4 MiB of unrelated memory written before each round (more than this machine's
//!   L2 of 1 MiB per core), only the round timed: a process whose data others pushed out of
//!   its caches. In the barrier every process runs after another one on its core, so the
//!   multi-process run pays something between the two;
//! - `idle`: before each round the thread only reads the clock for 5, 50 or 200 µs, touching
//!   none of its data, and only the round is timed: what time alone does to a process's
//!   caches and predictors on this machine. A round of the barrier comes 5 to 8 µs after
//!   the same process's last one.
//!
//! (Round at 4 trials minus round at 1) / 3 is the cost of a trial.

use clap::Parser;
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use flockstep_supervisor::cli::Cli;
use flockstep_supervisor::config::RunConfig;
use flockstep_supervisor::inproc::Simulation;
use std::hint::black_box;
use std::time::{Duration, Instant};

/// Rounds run before measuring: about 20 000 episodes of s3 per trial.
const TRAINING_ROUNDS: u64 = 300_000;
/// Memory written before each cold round; larger than one core's L2.
const EVICTION_BYTES: usize = 4 << 20;
/// How long the thread idles before each `idle` round.
const IDLE_GAPS: [Duration; 3] =
    [Duration::from_micros(5), Duration::from_micros(50), Duration::from_micros(200)];

/// The in-process runner's simulation (the main job's configuration: s3, 2 UAVs, seed 7)
/// with `trials` trials, trained for [`TRAINING_ROUNDS`].
fn trained(trials: usize) -> Simulation {
    let args = format!("supervisor --uavs 2 --trials {trials} --seed 7 --eval-episodes 0");
    let cli = Cli::parse_from(args.split(' '));
    let mut config = RunConfig::resolve(&cli.run).expect("the main job's configuration");
    config.episodes.train_episodes = u64::MAX;
    let mut simulation = Simulation::new(&config).expect("a simulation of s3");
    for _ in 0..TRAINING_ROUNDS {
        round(&mut simulation);
    }
    simulation
}

/// One barrier round.
fn round(simulation: &mut Simulation) {
    let stop = simulation.act().expect("the agents answer");
    assert!(!stop, "an endless training budget never stops");
    black_box(simulation.step().expect("the world takes the answers").count());
}

/// Reads the clock until `gap` has passed, and nothing else.
fn idle(gap: Duration) {
    let start = Instant::now();
    while start.elapsed() < gap {}
}

/// Times `iters` rounds, each after `before` has run untimed.
fn timed_rounds(simulation: &mut Simulation, iters: u64, mut before: impl FnMut()) -> Duration {
    let mut timed = Duration::ZERO;
    for _ in 0..iters {
        before();
        let start = Instant::now();
        round(simulation);
        timed += start.elapsed();
    }
    timed
}

/// Writes one byte in every cache line of `memory`.
fn evict(memory: &mut [u8]) {
    for line in memory.chunks_exact_mut(64) {
        line[0] = line[0].wrapping_add(1);
    }
    black_box(memory);
}

fn rounds(c: &mut Criterion) {
    let mut group = c.benchmark_group("round");
    let mut eviction = vec![0u8; EVICTION_BYTES];
    for trials in [1, 4] {
        let mut simulation = trained(trials);
        group.bench_function(BenchmarkId::new("warm", format!("trials={trials}")), |b| {
            b.iter(|| round(&mut simulation))
        });
        group.bench_function(BenchmarkId::new("cold", format!("trials={trials}")), |b| {
            b.iter_custom(|iters| timed_rounds(&mut simulation, iters, || evict(&mut eviction)))
        });
        for gap in IDLE_GAPS {
            let id =
                BenchmarkId::new("idle", format!("trials={trials}/gap_us={}", gap.as_micros()));
            group.bench_function(id, |b| {
                b.iter_custom(|iters| timed_rounds(&mut simulation, iters, || idle(gap)))
            });
        }
    }
    group.finish();
}

criterion_group!(benches, rounds);
criterion_main!(benches);
