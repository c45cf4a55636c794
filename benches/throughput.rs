//! The product's throughput against the raw barrier, in one invocation so that the ratios
//! are meaningful on a noisy machine: the raw iceoryx2 lockstep barrier (world + N agents,
//! no simulation work, the product's default waiting strategy; `common/raw_barrier.rs`), the
//! real `supervisor` over shared memory (`--transport shm`) and in one process
//! (`--transport inproc`), each at 1 and 4 trials.
//!
//! `cargo bench --bench throughput -- [--uavs N].. [--scenario S] [--seconds S] [--repeats K]`
//! (default: 2 UAVs, 5 s, 5 repetitions) prints on stdout one `throughput what=...` line per
//! configuration (the median over the repetitions), then `throughput ratio ...` and
//! `throughput target ...` lines; each single run is logged on stderr. A repetition runs
//! every configuration once, one after the other; each ratio is computed within a
//! repetition, whose runs share the machine's foreign load, and its median is reported.
//!
//! A product run trains for a calibrated number of `--episodes` (about `--seconds` of work)
//! with `--eval-episodes 0`: the greedy evaluation's length depends on how well each trial
//! learned (an untrained trial runs every episode to the tick cap), which would make the
//! work neither proportional to `--episodes` nor equal across trials. Start-up and shutdown
//! are measured by a run of one episode just before and subtracted: `rounds_per_s` is
//! (rounds - rounds of the one-episode run) / (wall - its wall), both from `summary.json`;
//! `summary_rounds_per_s` is the product's own figure, start-up included.
//!
//! A scenario with fewer routes than `--uavs` is skipped. Without `--bench` (as under
//! `cargo test --all-targets`) it does one short smoke run of every kind instead.

#[path = "common/raw_barrier.rs"]
mod raw_barrier;

use flockstep_proto::transport::{leftover_files, WaitPolicy};
use flockstep_proto::MAX_AGENTS;
use flockstep_supervisor::config::default_scenario;
use flockstep_world::Scenario;
use raw_barrier::{children_cpu_us, load1, measure, Error, Measurement};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

/// The trial counts measured for each transport.
const TRIALS: [usize; 2] = [1, 4];
/// Training episodes of a smoke run (no calibration).
const SMOKE_EPISODES: u64 = 20;
/// Episodes of the first in-process run that maps episodes to rounds; each next one has 4
/// times more.
const FIRST_PROBE: f64 = 64.0;
/// Rounds of the first calibration run of a configuration; each next one has 4 times more.
const FIRST_PROBE_ROUNDS: f64 = 10_000.0;
/// Runs of 4 times more episodes or rounds that a lookup or a calibration makes at most
/// (4^12 times the first is far past any `--seconds`): past it, something is wrong.
const MAX_PROBES: usize = 12;
/// A supervisor run that lasts longer hangs: it is killed and the bench fails naming it.
const RUN_BOUND: Duration = Duration::from_secs(600);

fn main() {
    raw_barrier::bench_main("throughput", parent);
}

struct Options {
    /// `--bench` given: measure; otherwise a smoke run.
    full: bool,
    uavs: Vec<usize>,
    /// Passed to the supervisor as `--scenario` (None: its default for the number of UAVs).
    scenario: Option<String>,
    seconds: f64,
    repeats: usize,
}

impl Options {
    fn parse(args: &[String]) -> Result<Options, Error> {
        // `cargo bench` passes `--bench`; `cargo test --all-targets` runs this binary without.
        let full = args.iter().any(|a| a == "--bench");
        let mut options = Options {
            full,
            uavs: Vec::new(),
            scenario: None,
            seconds: if full { 5.0 } else { 0.2 },
            repeats: if full { 5 } else { 1 },
        };
        let mut it = args.iter();
        while let Some(arg) = it.next() {
            let mut value = || it.next().ok_or_else(|| format!("{arg} needs a value"));
            match arg.as_str() {
                "--uavs" => options.uavs.push(value()?.parse()?),
                "--scenario" => options.scenario = Some(value()?.clone()),
                "--seconds" => options.seconds = value()?.parse()?,
                "--repeats" => options.repeats = value()?.parse::<usize>()?.max(1),
                // Other harness flags mean nothing here.
                _ => {}
            }
        }
        if options.uavs.is_empty() {
            options.uavs.push(2);
        }
        if let Some(n) = options.uavs.iter().find(|&&n| n == 0 || n > MAX_AGENTS) {
            return Err(format!("--uavs {n}: must be 1..={MAX_AGENTS}").into());
        }
        Ok(options)
    }
}

fn parent(args: &[String]) -> Result<(), Error> {
    let options = Options::parse(args)?;
    let mut bench = Bench::new(options.full)?;
    for &uavs in &options.uavs {
        let scenario = options.scenario.clone().unwrap_or_else(|| default_scenario(uavs));
        let routes = Scenario::resolve(&scenario)
            .map_err(|e| format!("--scenario {scenario}: {e}"))?
            .n_routes();
        if routes < uavs {
            println!(
                "throughput what=skipped uavs={uavs} scenario={scenario} routes={routes} \
                 reason=too-few-routes"
            );
            continue;
        }
        compare(&mut bench, &options, uavs, &scenario)?;
    }
    Ok(())
}

/// Measures every configuration for `uavs` agents, interleaved, and prints the medians and
/// the figures of merit.
fn compare(bench: &mut Bench, options: &Options, uavs: usize, scenario: &str) -> Result<(), Error> {
    let configs: Vec<Config> = [Transport::Shm, Transport::Inproc]
        .into_iter()
        .flat_map(|transport| {
            TRIALS.map(|trials| Config { transport, uavs, trials, scenario: scenario.into() })
        })
        .collect();
    let episodes = configs
        .iter()
        .map(
            |c| if options.full { bench.calibrate(c, options.seconds) } else { Ok(SMOKE_EPISODES) },
        )
        .collect::<Result<Vec<_>, _>>()?;
    let mut repetitions = Vec::new();
    for repeat in 0..options.repeats {
        let run_id = format!("tpb{}-{uavs}-{repeat}", std::process::id());
        let raw = measure(&run_id, uavs, WaitPolicy::default(), options.seconds)?;
        eprintln!("throughput run what=raw-barrier agents={uavs} rounds_per_s={:.0}", raw.rate());
        let mut product = Vec::new();
        for (config, &episodes) in configs.iter().zip(&episodes) {
            let startup = bench.run(config, 1)?;
            let p = Product::new(episodes, startup, bench.run(config, episodes)?)?;
            eprintln!(
                "throughput run what={} uavs={uavs} trials={} rounds_per_s={:.0} \
                 env_steps_per_s={:.0} seconds={:.3} startup_s={:.3}",
                config.transport.name(),
                config.trials,
                p.rounds_per_s(),
                p.env_steps_per_s(),
                p.run.wall,
                p.startup.wall
            );
            product.push(p);
        }
        repetitions.push(Repetition { raw, product });
    }
    let mut raw: Vec<&Measurement> = repetitions.iter().map(|r| &r.raw).collect();
    raw.sort_by(|a, b| a.rate().total_cmp(&b.rate()));
    print_raw(&raw, uavs, options);
    for (i, config) in configs.iter().enumerate() {
        let mut runs: Vec<&Product> = repetitions.iter().map(|r| &r.product[i]).collect();
        runs.sort_by(|a, b| a.rounds_per_s().total_cmp(&b.rounds_per_s()));
        print_product(&runs, config);
    }
    println!(
        "throughput summary uavs={uavs} scenario={scenario} repeats={} seconds={} full={}",
        options.repeats, options.seconds, options.full
    );
    // Each figure is computed within a repetition, whose runs follow each other closely and
    // so share the machine's foreign load, and the median over the repetitions is reported.
    let per_repetition: Vec<Vec<Figure>> =
        repetitions.iter().map(|r| figures(r, &configs)).collect();
    for (i, figure) in per_repetition[0].iter().enumerate() {
        let mut values: Vec<f64> = per_repetition.iter().map(|f| f[i].value).collect();
        values.sort_by(f64::total_cmp);
        let target = figure.target.map_or(String::new(), |t| {
            let met = if values[values.len() / 2] >= t { "yes" } else { "no" };
            format!(" target={} met={met}", number(t))
        });
        println!(
            "throughput {} name={} uavs={uavs} trials={} value={} min={} max={}{target}",
            figure.kind,
            figure.name,
            figure.trials,
            number(values[values.len() / 2]),
            number(values[0]),
            number(values[values.len() - 1]),
        );
    }
    Ok(())
}

/// Ratios with 3 decimals, rates as integers.
fn number(value: f64) -> String {
    if value.abs() >= 1000.0 {
        format!("{value:.0}")
    } else {
        format!("{value:.3}")
    }
}

fn print_raw(sorted: &[&Measurement], uavs: usize, options: &Options) {
    let policy = WaitPolicy::default();
    println!(
        "throughput what=raw-barrier agents={uavs} spins={} yields={} yield_for_us={} backoff_ms={} seconds={} {}",
        policy.spins,
        policy.yields,
        policy.yield_for.as_micros(),
        policy.backoff.as_millis(),
        options.seconds,
        Measurement::describe(sorted),
    );
}

fn print_product(sorted: &[&Product], config: &Config) {
    let median = sorted[sorted.len() / 2];
    let run = &median.run;
    println!(
        "throughput what={} uavs={} trials={} scenario={} episodes={} rounds={} env_steps={} \
         rounds_per_s={:.0} env_steps_per_s={:.0} min={:.0} max={:.0} \
         summary_rounds_per_s={:.0} summary_env_steps_per_s={:.0} wall_s={:.3} startup_s={:.3} \
         startup_process_s={:.3} process_s={:.3} cpu_us_per_round={:.2} occupancy={:.3} \
         startup_subtracted={} repeats={} load1={:.2}",
        config.transport.name(),
        config.uavs,
        config.trials,
        config.scenario,
        median.episodes,
        run.rounds,
        run.env_steps,
        median.rounds_per_s(),
        median.env_steps_per_s(),
        sorted[0].rounds_per_s(),
        sorted[sorted.len() - 1].rounds_per_s(),
        run.rounds as f64 / run.wall,
        run.env_steps as f64 / run.wall,
        run.wall,
        median.startup.wall,
        median.startup.process,
        run.process,
        median.cpu_us_per_round(),
        run.env_steps as f64 / (run.rounds * (config.trials * config.uavs) as u64).max(1) as f64,
        sorted.iter().all(|p| p.subtracted),
        sorted.len(),
        run.load1,
    );
}

/// One interleaved repetition: the raw barrier, then every product configuration.
struct Repetition {
    raw: Measurement,
    /// In the order of the configurations.
    product: Vec<Product>,
}

/// A figure of merit the issue asks for, from one repetition.
struct Figure {
    /// `ratio` or `target` (an absolute rate).
    kind: &'static str,
    name: &'static str,
    trials: String,
    value: f64,
    target: Option<f64>,
}

fn figures(repetition: &Repetition, configs: &[Config]) -> Vec<Figure> {
    let find = |transport: Transport, trials: usize| {
        let i = configs
            .iter()
            .position(|c| c.transport == transport && c.trials == trials)
            .expect("every transport is measured at every trial count");
        &repetition.product[i]
    };
    let ratio = |name, trials, value, target| Figure { kind: "ratio", name, trials, value, target };
    let mut figures = Vec::new();
    let raw = &repetition.raw;
    for trials in TRIALS {
        let shm = find(Transport::Shm, trials);
        let value = shm.rounds_per_s() / raw.rate();
        figures.push(ratio("shm_rounds_vs_raw_barrier", trials.to_string(), value, Some(0.8)));
        // CPU per round of every process together: less sensitive to foreign load.
        let value = shm.cpu_us_per_round() / (raw.cpu_us / raw.rounds.max(1) as f64);
        figures.push(ratio("shm_cpu_per_round_vs_raw_barrier", trials.to_string(), value, None));
    }
    let [one, four] = TRIALS.map(|trials| find(Transport::Shm, trials));
    let trials = format!("{}/{}", TRIALS[1], TRIALS[0]);
    let value = four.env_steps_per_s() / one.env_steps_per_s();
    figures.push(ratio("shm_env_steps_trials", trials.clone(), value, Some(3.5)));
    let value = four.rounds_per_s() / one.rounds_per_s();
    figures.push(ratio("shm_rounds_trials", trials, value, None));
    for trials in TRIALS {
        let (inproc, shm) = (find(Transport::Inproc, trials), find(Transport::Shm, trials));
        let value = inproc.rounds_per_s() / shm.rounds_per_s();
        figures.push(ratio("inproc_vs_shm_rounds", trials.to_string(), value, None));
        let value = inproc.env_steps_per_s() / shm.env_steps_per_s();
        figures.push(ratio("inproc_vs_shm_env_steps", trials.to_string(), value, None));
    }
    figures.push(Figure {
        kind: "target",
        name: "inproc_env_steps_per_s",
        trials: TRIALS[1].to_string(),
        value: find(Transport::Inproc, TRIALS[1]).env_steps_per_s(),
        target: Some(5e6),
    });
    figures
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Transport {
    Shm,
    Inproc,
}

impl Transport {
    fn name(self) -> &'static str {
        match self {
            Transport::Shm => "shm",
            Transport::Inproc => "inproc",
        }
    }
}

/// One configuration of the product.
#[derive(Debug, Clone)]
struct Config {
    transport: Transport,
    uavs: usize,
    trials: usize,
    scenario: String,
}

/// What one supervisor run reported.
struct Run {
    rounds: u64,
    env_steps: u64,
    /// `wall_seconds` of `summary.json`: from before the processes start to after they exit.
    wall: f64,
    /// The supervisor process from exec to exit, as this bench saw it.
    process: f64,
    /// CPU of the supervisor and every process it waited for.
    cpu_us: f64,
    load1: f64,
}

/// A run and the one-episode run measured just before it, whose figures are subtracted.
struct Product {
    episodes: u64,
    startup: Run,
    run: Run,
    /// False if the start-up could not be subtracted: noise made the one-episode run the
    /// longer, which only a smoke run is short enough for. The whole run counts then.
    subtracted: bool,
}

impl Product {
    fn new(episodes: u64, startup: Run, run: Run) -> Result<Product, Error> {
        // Both runs are deterministic and start alike, so only a misconfiguration can give
        // the longer run no more rounds.
        if run.rounds <= startup.rounds {
            return Err(format!(
                "a run of {episodes} episodes has {} rounds, the one-episode run {}",
                run.rounds, startup.rounds
            )
            .into());
        }
        let subtracted = run.wall > startup.wall;
        Ok(Product { episodes, startup, run, subtracted })
    }

    /// `figure` of the run minus that of the one-episode run (if subtracted).
    fn beyond(&self, figure: impl Fn(&Run) -> f64) -> f64 {
        figure(&self.run) - if self.subtracted { figure(&self.startup) } else { 0.0 }
    }

    fn rounds_per_s(&self) -> f64 {
        self.beyond(|r| r.rounds as f64) / self.beyond(|r| r.wall)
    }

    fn env_steps_per_s(&self) -> f64 {
        self.beyond(|r| r.env_steps as f64) / self.beyond(|r| r.wall)
    }

    fn cpu_us_per_round(&self) -> f64 {
        self.beyond(|r| r.cpu_us) / self.beyond(|r| r.rounds as f64)
    }
}

/// Runs the supervisor that cargo built for this bench.
struct Bench {
    supervisor: PathBuf,
    /// Results directories of the runs, removed on drop.
    out: tempfile::TempDir,
    runs: usize,
    /// Rounds by training episodes of each (UAVs, trials, scenario), from in-process runs.
    curves: HashMap<(usize, usize, String), Vec<CurvePoint>>,
}

/// One in-process run of the calibration.
#[derive(Clone, Copy)]
struct CurvePoint {
    episodes: f64,
    rounds: f64,
    seconds: f64,
}

impl Bench {
    /// Checks, when measuring, that the supervisor is the optimised build of this invocation.
    fn new(full: bool) -> Result<Bench, Error> {
        let supervisor = PathBuf::from(env!("CARGO_BIN_EXE_supervisor"));
        // This bench is `target/<profile>/deps/throughput-<hash>`, the binaries
        // `target/<profile>/<name>`: the same directory means the same profile.
        let me = std::env::current_exe()?;
        let same_profile = me.parent().and_then(Path::parent) == supervisor.parent();
        let profile = supervisor.parent().and_then(Path::file_name).unwrap_or_default();
        println!(
            "throughput what=setup supervisor={} profile={} debug_assertions={} same_profile={}",
            supervisor.display(),
            profile.to_string_lossy(),
            cfg!(debug_assertions),
            same_profile
        );
        if full && (cfg!(debug_assertions) || !same_profile) {
            return Err(format!(
                "{} is not the optimised build of this bench ({}): run `cargo bench`",
                supervisor.display(),
                me.display()
            )
            .into());
        }
        Ok(Bench { supervisor, out: tempfile::tempdir()?, runs: 0, curves: HashMap::new() })
    }

    /// One supervisor run of `config` training `episodes` episodes per trial.
    fn run(&mut self, config: &Config, episodes: u64) -> Result<Run, Error> {
        self.runs += 1;
        let run_id = format!("tp{}-{}", std::process::id(), self.runs);
        let out = self.out.path().join(&run_id);
        let mut command = Command::new(&self.supervisor);
        command
            .args(["--transport", config.transport.name(), "--quiet", "--run-id", &run_id])
            .args(["--scenario", &config.scenario])
            .args(["--uavs", &config.uavs.to_string()])
            .args(["--trials", &config.trials.to_string()])
            .args(["--episodes", &episodes.to_string(), "--eval-episodes", "0"])
            .arg("--out")
            .arg(&out);
        let load1 = load1();
        let cpu_before = children_cpu_us();
        let started = Instant::now();
        let output = output_within(&mut command, RUN_BOUND)?;
        let process = started.elapsed().as_secs_f64();
        let cpu_us = children_cpu_us() - cpu_before;
        if !output.status.success() {
            return Err(format!(
                "{command:?}: {}\nstdout: {}\nstderr: {}",
                output.status,
                String::from_utf8_lossy(&output.stdout),
                String::from_utf8_lossy(&output.stderr)
            )
            .into());
        }
        let path = out.join("summary.json");
        let summary: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path)?)?;
        let field = |name: &str| {
            summary.get(name).ok_or_else(|| format!("{} lacks {name}", path.display()))
        };
        if field("complete")?.as_bool() != Some(true) {
            return Err(format!("{command:?}: the run is not complete ({})", path.display()).into());
        }
        let number = |name: &str| -> Result<f64, Error> {
            Ok(field(name)?.as_f64().ok_or_else(|| format!("{}: {name}", path.display()))?)
        };
        let run = Run {
            rounds: number("rounds")? as u64,
            env_steps: number("env_steps")? as u64,
            wall: number("wall_seconds")?,
            process,
            cpu_us,
            load1,
        };
        let leftover = leftover_files(&run_id)?;
        if !leftover.is_empty() {
            return Err(format!("{command:?} left in shared memory: {leftover:?}").into());
        }
        // The results of a long run are large; keep the temporary directory small.
        std::fs::remove_dir_all(&out)?;
        Ok(run)
    }

    /// Training episodes for about `seconds` of work of `config`, start-up excluded. Its rate
    /// in rounds/s comes from probe runs of 4 times more rounds each, until one takes an
    /// eighth of that; the episodes for the rounds wanted then come from
    /// [`Bench::episodes_for`]. (Episodes shorten as the UAVs learn: a time per episode
    /// measured early would not extrapolate.)
    fn calibrate(&mut self, config: &Config, seconds: f64) -> Result<u64, Error> {
        let startup = self.run(config, 1)?;
        let mut rounds = FIRST_PROBE_ROUNDS;
        for _ in 0..MAX_PROBES {
            let episodes = self.episodes_for(config, rounds, seconds)?;
            let probe = self.run(config, episodes)?;
            let took = probe.wall - startup.wall;
            if took >= seconds / 8.0 {
                let rate = probe.rounds.saturating_sub(startup.rounds) as f64 / took;
                let episodes = self.episodes_for(config, rate * seconds, seconds)?;
                eprintln!(
                    "throughput calibrate what={} uavs={} trials={} probe_rounds={} \
                     probe_s={took:.3} rounds_per_s={rate:.0} episodes={episodes}",
                    config.transport.name(),
                    config.uavs,
                    config.trials,
                    probe.rounds,
                );
                return Ok(episodes);
            }
            rounds *= 4.0;
        }
        Err(format!("{config:?}: no run of up to {rounds} rounds took {seconds} s / 8").into())
    }

    /// The training episodes of a run of about `rounds` rounds. A number of episodes takes
    /// the same rounds with either transport (same seeds, same `World`), so they are looked
    /// up with fast in-process runs of 4 times more episodes each and interpolated on a
    /// log-log scale; past the first run that takes a quarter of `seconds`, extrapolated.
    fn episodes_for(&mut self, config: &Config, rounds: f64, seconds: f64) -> Result<u64, Error> {
        let inproc = Config { transport: Transport::Inproc, ..config.clone() };
        let key = (config.uavs, config.trials, config.scenario.clone());
        loop {
            let points = self.curves.entry(key.clone()).or_default();
            let last = points.last().copied();
            let covered = last.is_some_and(|p| p.rounds >= rounds || p.seconds >= seconds / 4.0);
            if covered && points.len() >= 2 {
                break;
            }
            if points.len() >= MAX_PROBES {
                return Err(
                    format!("{config:?}: {MAX_PROBES} runs never reached {rounds} rounds").into()
                );
            }
            let episodes = last.map_or(FIRST_PROBE, |p| p.episodes * 4.0);
            let run = self.run(&inproc, episodes as u64)?;
            let point = CurvePoint { episodes, rounds: run.rounds as f64, seconds: run.wall };
            self.curves.entry(key.clone()).or_default().push(point);
        }
        let points = &self.curves[&key];
        // The first point at or past `rounds` (else the last) and the one before it.
        let i = points.iter().position(|p| p.rounds >= rounds).unwrap_or(points.len() - 1).max(1);
        let (a, b) = (points[i - 1], points[i]);
        let fraction = (rounds / a.rounds).ln() / (b.rounds / a.rounds).ln();
        Ok((a.episodes * (b.episodes / a.episodes).powf(fraction)).round().max(2.0) as u64)
    }
}

/// Runs `command` to its end and returns its output, as `Command::output` does, but kills it
/// and fails if it runs longer than `bound`. A watchdog thread waits for the bound, so the
/// measured processes share the machine with no polling.
fn output_within(command: &mut Command, bound: Duration) -> Result<Output, Error> {
    let child = command
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()?;
    let pid = child.id();
    let (done, finished) = std::sync::mpsc::channel::<()>();
    let watchdog = std::thread::spawn(move || {
        let overdue = finished.recv_timeout(bound).is_err();
        if overdue {
            // SAFETY: kill(2) on our own child's pid. Only `wait_with_output` reaps it, and
            // at the bound that is still waiting (the thread signals `done` once it has).
            unsafe {
                libc::kill(pid as libc::pid_t, libc::SIGKILL);
            }
        }
        overdue
    });
    let output = child.wait_with_output();
    let _ = done.send(());
    let overdue = watchdog.join().map_err(|_| "the watchdog thread panicked")?;
    if overdue {
        return Err(format!("{command:?} still ran after {bound:?}: killed").into());
    }
    Ok(output?)
}
