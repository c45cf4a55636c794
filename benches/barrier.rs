//! The raw lockstep barrier over iceoryx2, without any simulation work: one world process
//! and N agent processes exchange an `Observation` and N `Action`s per round through
//! `flockstep_proto::transport`, exactly as a run does. It measures rounds/s, round-trip
//! percentiles and CPU per round for several waiting strategies in one invocation, so their
//! ratios are meaningful on the machine at hand.
//!
//! `cargo bench --bench barrier -- [--agents N].. [--seconds S] [--repeats K] [--policy S/Y[/T[/B]]]..`
//! (S spins, Y yields, then yielding until T µs into the wait, and blocking at once for B ms
//! after stalled yielding; T and B default to the product's)
//! prints one line per configuration on stdout, e.g.
//! `barrier agents=2 strategy=yield-block spins=0 yields=32 yield_for_us=200 rounds_per_s=...`.
//! Without `--bench` (as under `cargo test --all-targets`) it does a short smoke run. The
//! binary re-executes itself (`--child-world`, `--child-agent`) for the processes; the
//! barrier itself is `common/raw_barrier.rs`, which `benches/throughput.rs` shares.

#[path = "common/raw_barrier.rs"]
mod raw_barrier;

use flockstep_proto::transport::WaitPolicy;
use flockstep_proto::MAX_AGENTS;
use raw_barrier::{measure, parse_policy, Error, Measurement};
use std::time::Duration;

fn main() {
    raw_barrier::bench_main("barrier", parent);
}

fn parent(args: &[String]) -> Result<(), Error> {
    // `cargo bench` passes `--bench`; `cargo test --all-targets` runs this binary without it,
    // and then a short smoke run keeps the test suite fast while still exercising the barrier.
    let full = args.iter().any(|a| a == "--bench");
    let mut agents = Vec::new();
    let mut policies = Vec::new();
    let (mut seconds, mut repeats) = if full { (1.0_f64, 3_usize) } else { (0.2, 1) };
    let mut it = args.iter();
    while let Some(arg) = it.next() {
        let mut value = || it.next().ok_or_else(|| format!("{arg} needs a value"));
        match arg.as_str() {
            "--agents" => agents.push(value()?.parse::<usize>()?),
            "--seconds" => seconds = value()?.parse()?,
            "--repeats" => repeats = value()?.parse::<usize>()?.max(1),
            "--policy" => {
                policies.push(parse_policy(value()?)?);
            }
            // Other harness flags mean nothing here.
            _ => {}
        }
    }
    if agents.is_empty() {
        agents = if full { vec![2, 8] } else { vec![2] };
    }
    if policies.is_empty() {
        // Blocking at once, the tuned default, the default blocking right after its counted
        // yields, and the default with a spin phase in front.
        policies = vec![
            WaitPolicy::BLOCK,
            WaitPolicy::default(),
            WaitPolicy { yield_for: Duration::ZERO, ..WaitPolicy::default() },
            WaitPolicy { spins: 100, ..WaitPolicy::default() },
        ];
    }
    if let Some(n) = agents.iter().find(|&&n| n == 0 || n > MAX_AGENTS) {
        return Err(format!("--agents {n}: must be 1..={MAX_AGENTS}").into());
    }
    for &n in &agents {
        // Interleaved repeats: the machine is shared, so a burst of foreign load hits every
        // policy alike instead of skewing one, and the median discards the outliers.
        let mut runs: Vec<Vec<Measurement>> = policies.iter().map(|_| Vec::new()).collect();
        for repeat in 0..repeats {
            for (i, policy) in policies.iter().enumerate() {
                let run_id = format!("bench-{}-{n}-{i}-{repeat}", std::process::id());
                runs[i].push(measure(&run_id, n, *policy, seconds)?);
            }
        }
        let mut baseline = None;
        for (policy, mut measured) in policies.iter().zip(runs) {
            measured.sort_by(|a, b| a.rate().total_cmp(&b.rate()));
            let sorted: Vec<&Measurement> = measured.iter().collect();
            let rate = sorted[sorted.len() / 2].rate();
            let base = *baseline.get_or_insert(rate);
            println!(
                "barrier agents={n} strategy={} spins={} yields={} yield_for_us={} backoff_ms={} vs_first={:.2} {}",
                strategy(policy),
                policy.spins,
                policy.yields,
                policy.yield_for.as_micros(),
                policy.backoff.as_millis(),
                rate / base,
                Measurement::describe(&sorted),
            );
        }
    }
    Ok(())
}

fn strategy(policy: &WaitPolicy) -> &'static str {
    match (policy.spins > 0, policy.yields > 0) {
        (false, false) => "block",
        (true, false) => "spin-block",
        (false, true) => "yield-block",
        (true, true) => "spin-yield-block",
    }
}
