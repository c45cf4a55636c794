//! Tests of `flockstep_proto::transport` over real iceoryx2 services.
//!
//! Each test owns a run id (hence its own files in /dev/shm), so the tests run in parallel
//! without meeting. Every wait is bounded and says what it waited for when it fails.

use flockstep_proto::services::MAX_RUN_ID;
use flockstep_proto::supervisor_to_world::Control;
use flockstep_proto::transport::{
    cleanup_run, iceoryx_root, leftover_files, sweep_stale_runs, AgentPorts, FromWorld, RunConfig,
    RunServices, SenderNode, SignalMode, SupervisorPorts, TransportError, LOOK_FOR_GONE_WORLD,
};
use flockstep_proto::{Action, EpisodeReport, Membership, Observation};
use std::io::BufRead;
use std::os::unix::fs::MetadataExt;
use std::time::Duration;

const BOUND: Duration = Duration::from_secs(5);

/// A run id unique to this test and this test process.
fn run(test: &str) -> RunConfig {
    let mut config =
        RunConfig::new(format!("t-{test}-{}", std::process::id()), SignalMode::Untouched);
    config.open_timeout = BOUND;
    config
}

/// The supervisor's next episode record, for the tests that change no membership (so
/// nothing else comes).
fn try_episode(supervisor: &SupervisorPorts) -> Result<Option<EpisodeReport>, TransportError> {
    match supervisor.try_next()? {
        Some(FromWorld::Episode(report)) => Ok(Some(report)),
        Some(other) => panic!("no membership was changed, yet the world told {other:?}"),
        None => Ok(None),
    }
}

/// Writes round `round` into a published sample, as the world does.
fn observation(round: u64) -> impl FnOnce(&mut Observation) {
    move |o| o.round = round
}

#[test]
fn world_agent_and_supervisor_exchange_every_message() {
    let config = run("roundtrip");
    let mut world = RunServices::create(&config).unwrap().into_world().unwrap();
    let agent = RunServices::open(&config).unwrap().into_agent().unwrap();
    let supervisor = RunServices::open(&config).unwrap().into_supervisor().unwrap();
    world.wait_for_peers(1, true, BOUND).unwrap();

    world.publish_observation(observation(7)).unwrap();
    let round = agent
        .waiter()
        .wait(&"observation of round 7", BOUND, || Ok(agent.try_observation()?.map(|o| o.round)))
        .unwrap();
    assert_eq!(round, 7);

    agent.publish_action(&Action { round: 7, ..Action::new(3) }).unwrap();
    let action = world.waiter().wait(&"action of round 7", BOUND, || world.try_action()).unwrap();
    assert_eq!((action.round, action.agent), (7, 3));

    world.queue_episode(&EpisodeReport { episode: 11, ..EpisodeReport::default() }).unwrap();
    world.flush_episodes().unwrap();
    let report =
        supervisor.waiter().wait(&"episode 11", BOUND, || try_episode(&supervisor)).unwrap();
    assert_eq!(report.episode, 11);

    supervisor.send_control(&Control { stop: 1, ..Control::default() }).unwrap();
    let (control, sender) =
        world.waiter().wait(&"stop command", BOUND, || world.try_control()).unwrap();
    assert_eq!(control.stop, 1);
    assert_eq!(sender.pid(), Some(std::process::id()), "the sender's process is known");
}

/// An agent that answered the stop round leaves once the world has (its last answer would
/// otherwise be lost now and then): the wait ends when the world's ports are gone, and
/// after its timeout while they are not.
#[test]
fn an_agent_waits_for_the_world_to_leave() {
    let config = run("world-gone");
    let world = RunServices::create(&config).unwrap().into_world().unwrap();
    let agent = RunServices::open(&config).unwrap().into_agent().unwrap();
    let stayed = agent.await_world_gone(Duration::from_millis(50)).unwrap();
    assert!(!stayed, "the world is still there");
    drop(world);
    assert!(agent.await_world_gone(BOUND).unwrap(), "the world has left");
}

#[test]
fn open_waits_until_the_world_has_created_the_services() {
    let config = run("openwait");
    let (opening_tx, opening) = std::sync::mpsc::channel();
    let opener = {
        let config = config.clone();
        // The ports are not Send: the thread opens, checks and drops them itself.
        std::thread::spawn(move || {
            opening_tx.send(()).expect("the test waits for the opener");
            RunServices::open(&config).map(|s| s.run_id().to_string())
        })
    };
    opening.recv_timeout(BOUND).expect("the opener thread starts");
    // Time to reach its wait; it cannot succeed before the world exists, nor give up
    // before `open_timeout` (5 s).
    std::thread::sleep(Duration::from_millis(100));
    assert!(!opener.is_finished(), "open returned before the world existed");
    let _world = RunServices::create(&config).unwrap().into_world().unwrap();
    let opened = opener.join().expect("opener thread panicked");
    assert_eq!(opened.unwrap(), config.run_id);
}

#[test]
fn open_without_a_world_times_out_naming_the_service() {
    let mut config = run("nowrld");
    config.open_timeout = Duration::from_millis(50);
    let error = RunServices::open(&config).err().expect("open must fail without a world");
    let text = error.to_string();
    assert!(matches!(error, TransportError::ServiceMissing { .. }), "{text}");
    assert!(text.contains("observations") && text.contains(&config.run_id), "{text}");
}

#[test]
fn a_second_world_for_the_same_run_is_refused() {
    let config = run("twice");
    let _first = RunServices::create(&config).unwrap();
    let error = RunServices::create(&config).err().expect("second create must fail");
    assert!(matches!(error, TransportError::RunInUse { .. }), "{error}");
}

#[test]
fn bad_run_ids_are_errors_not_panics() {
    for bad in ["", "a/b", "a.b", &"x".repeat(MAX_RUN_ID + 1)] {
        let error = RunServices::create(&RunConfig::new(bad, SignalMode::Untouched)).err();
        assert!(
            matches!(error, Some(TransportError::InvalidRunId(_))),
            "run id {bad:?}: {error:?}"
        );
    }
}

/// The user this test process runs as. Read here, not taken from the crate: the test of the
/// root checks the crate's choice against it.
fn effective_uid() -> u32 {
    // SAFETY: geteuid takes no arguments and cannot fail.
    unsafe { libc::geteuid() }
}

/// iceoryx2's shared default root (`/tmp/iceoryx2`) belongs to whichever user made it first;
/// a run keeps its node, service and socket files in this user's own private root instead.
#[test]
fn a_run_keeps_its_files_in_this_users_private_root() {
    let config = run("root");
    let _world = RunServices::create(&config).unwrap().into_world().unwrap();
    let root = iceoryx_root();
    let uid = effective_uid();
    assert_eq!(root, std::path::PathBuf::from(format!("/tmp/flockstep-{uid}")));
    let meta = std::fs::symlink_metadata(&root).unwrap();
    assert!(meta.is_dir(), "{}", root.display());
    assert_eq!(meta.uid(), uid, "{}", root.display());
    assert_eq!(
        meta.mode() & 0o022,
        0,
        "{} is writable by group or others: {:o}",
        root.display(),
        meta.mode()
    );
    let files = leftover_files(&config.run_id).unwrap();
    let in_root = files.iter().filter(|f| f.starts_with(&root)).count();
    assert!(in_root > 0, "no file of the live run under {}: {files:#?}", root.display());
    assert!(files.iter().all(|f| !f.starts_with("/tmp/iceoryx2")), "{files:#?}");
}

/// The longest run id still gives socket paths that fit the 108 bytes of a Unix socket path,
/// for this user and for the longest root there can be (`/tmp/flockstep-4294967295/`).
#[test]
fn the_longest_run_id_fits_every_users_socket_paths() {
    let mut config = run("long");
    config.run_id = format!("{:x<MAX_RUN_ID$}", config.run_id);
    let world = RunServices::create(&config).unwrap().into_world().unwrap();
    let _agent = RunServices::open(&config).unwrap().into_agent().unwrap();
    let _supervisor = RunServices::open(&config).unwrap().into_supervisor().unwrap();
    world.wait_for_peers(1, true, BOUND).unwrap();
    let files = leftover_files(&config.run_id).unwrap();
    let sockets: Vec<_> =
        files.iter().filter(|f| f.extension() == Some("event".as_ref())).collect();
    assert!(!sockets.is_empty(), "no event socket: {files:#?}");
    // Each is `<root>/flockstep.<run id>.<listener id>.event`, the listener id a number.
    let head = format!("flockstep.{}.", config.run_id);
    for socket in sockets {
        assert_eq!(socket.parent(), Some(iceoryx_root().as_path()), "{}", socket.display());
        let name = socket.file_name().and_then(|n| n.to_str()).expect("a UTF-8 name");
        let id = name.strip_prefix(&head).and_then(|rest| rest.strip_suffix(".event"));
        let id = id.unwrap_or_else(|| panic!("socket `{name}` is not named as assumed"));
        assert!(id.bytes().all(|b| b.is_ascii_digit()), "listener id `{id}`");
        assert!(id.len() <= LISTENER_ID_DIGITS, "listener id `{id}` has more digits than assumed");
    }
    // The longest root, for a 10-digit uid, and the most digits assumed of a listener id.
    let worst = "/tmp/flockstep-4294967295/".len() + head.len() + LISTENER_ID_DIGITS + 6;
    assert!(worst <= 108, "a socket path could have {worst} bytes");
}

/// The most digits a listener id has until its process made 12 000 of them (a `u128` whose
/// top 32 bits count the ids; see `services::MAX_RUN_ID`).
const LISTENER_ID_DIGITS: usize = 33;

#[test]
fn a_late_agent_gets_the_current_round_from_history() {
    let config = run("history");
    let world = RunServices::create(&config).unwrap().into_world().unwrap();
    world.publish_observation(observation(3)).unwrap();
    let agent = RunServices::open(&config).unwrap().into_agent().unwrap();
    // History reaches a new subscriber when the publisher updates its connections, which it
    // does on its next publish: the round published before the agent subscribed comes first.
    world.publish_observation(observation(4)).unwrap();
    let mut rounds = Vec::new();
    agent
        .waiter()
        .wait(&"rounds 3 and 4", BOUND, || {
            while let Some(o) = agent.try_observation()? {
                rounds.push(o.round);
            }
            Ok((rounds.len() >= 2).then_some(()))
        })
        .unwrap();
    assert_eq!(rounds, [3, 4], "round 3 from history, then round 4");
}

#[test]
fn an_action_loan_dropped_unsent_sends_nothing() {
    let config = run("loan");
    let world = RunServices::create(&config).unwrap().into_world().unwrap();
    let agent = RunServices::open(&config).unwrap().into_agent().unwrap();
    world.wait_for_peers(1, false, BOUND).unwrap();

    let mut abandoned = agent.loan_action().unwrap();
    abandoned.round = 5;
    drop(abandoned);
    let mut answer = agent.loan_action().unwrap();
    (answer.round, answer.agent, answer.n_trials) = (6, 1, 0);
    answer.send().unwrap();

    let action = world.waiter().wait(&"action of round 6", BOUND, || world.try_action()).unwrap();
    assert_eq!((action.round, action.agent), (6, 1), "the abandoned loan must not arrive");
    assert!(world.try_action().unwrap().is_none(), "exactly one action was sent");
}

#[test]
fn the_supervisor_sleeps_until_the_world_wakes_it() {
    let config = run("sleep");
    let mut world = RunServices::create(&config).unwrap().into_world().unwrap();
    let supervisor = RunServices::open(&config).unwrap().into_supervisor().unwrap();
    world.wait_for_peers(0, true, BOUND).unwrap();
    // Full batches go out without a flush; the wake-up comes with the batch that completes
    // `EPISODE_WAKE_EVERY` records.
    for episode in 0..flockstep_proto::transport::EPISODE_WAKE_EVERY {
        world.queue_episode(&EpisodeReport { episode, ..EpisodeReport::default() }).unwrap();
    }
    // The sleep ends at once, not at its bound.
    let long = Duration::from_secs(60);
    let started = std::time::Instant::now();
    supervisor.waiter().sleep(long).unwrap();
    let slept = started.elapsed();
    assert!(slept < long / 4, "slept {slept:?}: the world's wake-up was lost");
    let mut drained = 0;
    while try_episode(&supervisor).unwrap().is_some() {
        drained += 1;
    }
    assert_eq!(drained, flockstep_proto::transport::EPISODE_WAKE_EVERY);
}

#[test]
fn a_wait_that_times_out_says_what_it_waited_for() {
    let config = run("timeout");
    let _world = RunServices::create(&config).unwrap().into_world().unwrap();
    let agent = RunServices::open(&config).unwrap().into_agent().unwrap();
    let error = agent
        .waiter()
        .wait(&format_args!("observation of round {}", 42), Duration::from_millis(30), || {
            Ok(agent.try_observation()?.map(|o| o.round))
        })
        .unwrap_err();
    let text = error.to_string();
    assert!(matches!(error, TransportError::Timeout { .. }), "{text}");
    assert!(text.contains("round 42") && text.contains("wake/agents"), "{text}");
}

/// A block shorter than a microsecond ends: iceoryx2 hands the socket whole microseconds,
/// and a timeout of 0 there means none. Before, a wait whose deadline was under a
/// microsecond away blocked until a wake-up came, which a silent peer never sends. The
/// sleep runs on a thread of its own so that the test can say so instead of hanging.
#[test]
fn a_sleep_shorter_than_a_microsecond_ends() {
    let config = run("sub-microsecond");
    let _world = RunServices::create(&config).unwrap().into_world().unwrap();
    let (done, ended) = std::sync::mpsc::channel();
    let agent_config = config.clone();
    std::thread::spawn(move || {
        let agent = RunServices::open(&agent_config).unwrap().into_agent().unwrap();
        let slept = agent.waiter().sleep(Duration::from_nanos(500));
        done.send(slept.map_err(|e| e.to_string())).expect("the test waits for the result");
    });
    match ended.recv_timeout(BOUND) {
        Ok(slept) => slept.expect("a sleep of 500 ns"),
        Err(_) => panic!("a sleep of 500 ns had not ended after {BOUND:?}"),
    }
}

#[test]
fn nothing_of_a_run_is_left_after_every_process_dropped_its_ports() {
    let config = run("clean");
    {
        let world = RunServices::create(&config).unwrap().into_world().unwrap();
        let agent = RunServices::open(&config).unwrap().into_agent().unwrap();
        let _supervisor = RunServices::open(&config).unwrap().into_supervisor().unwrap();
        world.publish_observation(observation(1)).unwrap();
        agent.publish_action(&Action::new(0)).unwrap();
        let during = leftover_files(&config.run_id).unwrap();
        assert!(
            during.iter().any(|p| p.starts_with("/dev/shm")),
            "no shm files while running: {during:?}"
        );
    }
    let after = leftover_files(&config.run_id).unwrap();
    assert!(after.is_empty(), "left behind: {after:#?}");
}

/// Not a test of its own: the body of the child processes that `spawn_and_kill` starts.
#[test]
#[ignore = "child process of the tests that kill a process"]
fn child_process() {
    let (Ok(run_id), Ok(role)) =
        (std::env::var("FLOCKSTEP_TEST_CHILD_RUN"), std::env::var("FLOCKSTEP_TEST_CHILD_ROLE"))
    else {
        return;
    };
    let parent: u32 = std::env::var("FLOCKSTEP_TEST_PARENT").unwrap().parse().unwrap();
    flockstep_proto::transport::exit_with_parent(parent).unwrap();
    let signals = if role.starts_with("supervised") {
        SignalMode::Supervised
    } else if role.starts_with("interactive") {
        SignalMode::Interactive
    } else {
        SignalMode::Untouched
    };
    let mut config = RunConfig::new(run_id, signals);
    config.open_timeout = BOUND;
    if role.ends_with("signals") {
        // From every signal's default action, as a shell's foreground job starts: a test run
        // started in the background (`cargo test &`) ignores SIGINT and SIGQUIT, and its
        // children inherit that, which is not the transport's doing.
        for signal in ICEORYX2_SIGNALS {
            // SAFETY: restores the default disposition of a signal this process has no
            // handler for (the Rust runtime's are for SIGSEGV and SIGBUS).
            unsafe { libc::signal(signal, libc::SIG_DFL) };
        }
        // Every port of a run, and a wait that blocks on the listener.
        let world = RunServices::create(&config).unwrap().into_world().unwrap();
        let _agent = RunServices::open(&config).unwrap().into_agent().unwrap();
        let _supervisor = RunServices::open(&config).unwrap().into_supervisor().unwrap();
        let _ = world.waiter().wait(&"nothing", Duration::from_millis(20), || Ok(None::<()>));
        let status = std::fs::read_to_string("/proc/self/status").unwrap();
        for line in status.lines().filter(|l| l.starts_with("SigCgt:") || l.starts_with("SigIgn:"))
        {
            println!("{line}");
        }
        println!("child-ready");
        return;
    }
    if role == "world" {
        let world = RunServices::create(&config).unwrap().into_world().unwrap();
        println!("child-ready");
        // Rounds for an agent that opens later (a publisher reaches a new subscriber only
        // as it publishes), until killed.
        for round in 0..6000 {
            world.publish_observation(observation(round)).unwrap();
            std::thread::sleep(Duration::from_millis(10));
        }
        return;
    }
    if role == "supervised-opener" {
        // Its first node installs the SIGTERM latch; then it opens a run no world serves.
        let _agent = RunServices::open(&config).unwrap().into_agent().unwrap();
        println!("child-ready");
        let opened = RunServices::open(&unserved(&config)).map(|_| ());
        println!("child-result {opened:?}");
        return;
    }
    let agent = RunServices::open(&config).unwrap().into_agent().unwrap();
    println!("child-ready");
    if role == "supervised-agent" {
        let waited = agent.waiter().wait(
            &"an observation that never comes",
            Duration::from_secs(60),
            || Ok(agent.try_observation()?.map(|o| o.round)),
        );
        println!("child-result {waited:?}");
        return;
    }
    std::thread::sleep(Duration::from_secs(60));
}

/// A child process that is killed and reaped when dropped, so a failed assertion leaves
/// neither a running nor a stopped (SIGSTOP) child behind.
struct Child(std::process::Child);

impl std::ops::Deref for Child {
    type Target = std::process::Child;
    fn deref(&self) -> &std::process::Child {
        &self.0
    }
}

impl std::ops::DerefMut for Child {
    fn deref_mut(&mut self) -> &mut std::process::Child {
        &mut self.0
    }
}

impl Drop for Child {
    fn drop(&mut self) {
        // Fails only for a child already reaped, which is what is wanted.
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts `child_process` in `role` and waits until its ports exist; returns it with the
/// rest of its stdout and what it printed so far.
fn spawn_child(
    config: &RunConfig,
    role: &str,
) -> (Child, std::io::Lines<std::io::BufReader<std::process::ChildStdout>>, String) {
    let mut child = std::process::Command::new(std::env::current_exe().unwrap())
        .args(["--exact", "child_process", "--ignored", "--nocapture", "--test-threads=1"])
        .env("FLOCKSTEP_TEST_CHILD_RUN", &config.run_id)
        .env("FLOCKSTEP_TEST_CHILD_ROLE", role)
        .env("FLOCKSTEP_TEST_PARENT", std::process::id().to_string())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Bounded: the child prints the line within BOUND or exits (panicking), ending the stream.
    let mut lines = std::io::BufReader::new(child.stdout.take().unwrap()).lines();
    let mut seen = String::new();
    for line in lines.by_ref() {
        let line = line.unwrap();
        seen.push_str(&line);
        seen.push('\n');
        if line.contains("child-ready") {
            return (Child(child), lines, seen);
        }
    }
    let status = child.wait().unwrap();
    panic!("{role} child exited ({status}) before getting ready; stdout:\n{seen}");
}

/// A lock taken by the tests that leave a dead node and look at it before they clean it, and by
/// those that sweep: a sweep cleans the dead nodes of every run of this user, so run in
/// parallel it would clean another test's before that one looked. A lock on a file rather
/// than a mutex, so that it also holds between copies of this test binary run at the same
/// time (each open of the file is locked apart, so threads of one process exclude each other
/// too). A supervisor started meanwhile sweeps as well, without asking: the tests that
/// start supervisors (the workspace's integration tests) must not run beside these.
///
/// Returns the locked file, whose closing releases the lock; gives up after a bound long
/// enough for every other holder's tests.
fn dead_nodes_lock() -> std::fs::File {
    const WAIT: Duration = Duration::from_secs(300);
    let uid = effective_uid();
    let path = std::env::temp_dir().join(format!("flockstep-dead-node-tests-{uid}.lock"));
    let file = std::fs::File::create(&path)
        .unwrap_or_else(|e| panic!("cannot open the lock file {}: {e}", path.display()));
    let deadline = std::time::Instant::now() + WAIT;
    loop {
        match file.try_lock() {
            Ok(()) => return file,
            Err(std::fs::TryLockError::WouldBlock) if std::time::Instant::now() < deadline => {
                std::thread::sleep(Duration::from_millis(5));
            }
            Err(std::fs::TryLockError::WouldBlock) => {
                panic!("another test held the lock on {} for {WAIT:?}", path.display())
            }
            Err(std::fs::TryLockError::Error(e)) => {
                panic!("cannot lock {}: {e}", path.display())
            }
        }
    }
}

/// Cleans `config`'s run and checks that `dead_nodes` dead nodes were removed, none is left
/// counted as live, and nothing of the run is left on disk (`context` names the case).
fn assert_swept(config: &RunConfig, dead_nodes: usize, context: &str) {
    let cleaned = cleanup_run(&config.run_id).unwrap();
    assert_eq!((cleaned.dead_nodes, cleaned.live_nodes), (dead_nodes, 0), "{context} {cleaned:?}");
    let after = leftover_files(&config.run_id).unwrap();
    assert!(after.is_empty(), "{context} left behind after clean-up: {after:#?}");
}

/// A wait on a live world that lasts this long looks for the world's node twice: a wait
/// shorter than the first look would time out whatever the look decided.
fn past_two_looks() -> Duration {
    LOOK_FOR_GONE_WORLD.0 + LOOK_FOR_GONE_WORLD.1 + Duration::from_millis(300)
}

/// A wait on a world whose node is gone (its process killed: a zombie, then reaped) ends
/// within about a second (`LOOK_FOR_GONE_WORLD`), naming the world's process and what it waited for, instead
/// of at its deadline; a live world, or one stopped with SIGSTOP (a Ctrl-Z pauses the whole
/// run), leaves the wait to its deadline.
#[test]
fn a_wait_on_a_world_that_is_gone_ends_at_once() {
    let _sweeps = dead_nodes_lock();
    let config = run("world-dead");
    let (mut world, _, _) = spawn_child(&config, "world");
    let agent = RunServices::open(&config).unwrap().into_agent().unwrap();
    let first =
        agent.waiter().wait(&"the world's observation", BOUND, || agent.try_observation()).unwrap();
    let node = SenderNode::of(&first);
    assert_eq!(node.pid(), Some(world.id()), "the observation names its sender");
    assert_eq!(agent.world(), Some(node), "the world's node is its observation publisher's");
    let what = format_args!("observation of round {}", 9);
    let short = past_two_looks();
    let wait_on = |timeout| agent.wait_on_world(&what, timeout, || Ok(None::<()>));
    for (state, signal) in [("live", libc::SIGCONT), ("stopped", libc::SIGSTOP)] {
        // SAFETY: signalling our own child by pid.
        assert_eq!(unsafe { libc::kill(world.id() as libc::pid_t, signal) }, 0);
        let waited = wait_on(short);
        assert!(matches!(waited, Err(TransportError::Timeout { .. })), "{state}: {waited:?}");
    }
    world.kill().unwrap();
    let long = Duration::from_secs(60);
    for state in ["a zombie", "reaped"] {
        let started = std::time::Instant::now();
        let error = wait_on(long).unwrap_err();
        let text = error.to_string();
        let named = format!("the world (process {}) is gone", world.id());
        assert!(matches!(error, TransportError::WorldGone { .. }), "{state}: {text}");
        assert!(text.contains(&named) && text.contains("round 9"), "{state}: {text}");
        assert!(started.elapsed() < long / 2, "{state}: noticed after {:?}", started.elapsed());
        assert!(agent.await_world_gone(long).unwrap(), "{state}: the world is gone");
        if state == "a zombie" {
            world.wait().unwrap();
        }
    }
    // The last node out may have cleaned the world's dead node already.
    drop((first, agent));
    let cleaned = cleanup_run(&config.run_id).unwrap();
    assert_eq!(cleaned.live_nodes, 0, "{cleaned:?}");
    let after = leftover_files(&config.run_id).unwrap();
    assert!(after.is_empty(), "left behind after clean-up: {after:#?}");
}

/// An agent that never saw the world's publisher (it opened the run's services after the
/// world was killed and a clean-up removed the world's ports) knows the world by its node's
/// name: the wait ends within about a second, not at its deadline. A live world not yet
/// publishing (its services made, its ports not) leaves the wait to its deadline.
#[test]
fn a_wait_on_a_world_gone_before_the_agent_saw_it_ends_at_once_too() {
    let _sweeps = dead_nodes_lock();
    let unpublished = run("world-unpublished");
    let world = RunServices::create(&unpublished).unwrap();
    let agent = RunServices::open(&unpublished).unwrap().into_agent().unwrap();
    let short = past_two_looks();
    let waited = agent.wait_on_world(&"a round", short, || Ok(None::<()>));
    assert!(matches!(waited, Err(TransportError::Timeout { .. })), "live, unseen: {waited:?}");
    drop((agent, world));

    let config = run("world-unseen");
    let (world, keeper) = spawn_world(&config);
    kill_and_clean(world, &keeper);
    let agent = RunServices::open(&config).unwrap().into_agent().unwrap();
    assert_eq!(agent.world(), None, "the world's publisher went with its node");
    assert_noticed_gone(&agent, "the world (process unknown) is gone");
    drop((agent, keeper));
    assert_swept(&config, 0, "after the unseen world");
}

/// Starts a world child for `config` and opens the run's services, to keep them while the
/// world is killed.
fn spawn_world(config: &RunConfig) -> (Child, RunServices) {
    let (world, _, _) = spawn_child(config, "world");
    (world, RunServices::open(config).unwrap())
}

/// SIGKILLs and reaps `world`, and has `keeper` remove its node and ports.
fn kill_and_clean(mut world: Child, keeper: &RunServices) {
    world.kill().unwrap();
    world.wait().unwrap();
    assert_eq!(keeper.cleanup_dead_nodes(), 1, "the killed world's node is removed");
}

/// Waits on a gone world with a long deadline: the wait must end well before it, with
/// [`TransportError::WorldGone`] saying `named`.
fn assert_noticed_gone(agent: &AgentPorts, named: &str) {
    let long = Duration::from_secs(20);
    let started = std::time::Instant::now();
    let error = agent.wait_on_world(&"a round", long, || Ok(None::<()>)).unwrap_err();
    let text = error.to_string();
    assert!(matches!(error, TransportError::WorldGone { .. }), "{text}");
    assert!(text.contains(named), "{text}");
    assert!(started.elapsed() < long / 2, "noticed after {:?}", started.elapsed());
}

/// An agent that received an observation knows the world by it, even if none of its waits
/// lasted long enough to look for the world: when the world is killed and a clean-up removes
/// its ports before the agent first looks, the wait still names the world's process. (Once
/// the world was known only by listing the observation publishers, which a clean-up had
/// emptied: an attached agent's error said "process unknown" in one CI run.)
#[test]
fn an_agent_knows_the_world_by_its_first_observation() {
    let _sweeps = dead_nodes_lock();
    let config = run("world-known");
    let (world, keeper) = spawn_world(&config);
    let named = format!("the world (process {}) is gone", world.id());
    let agent = RunServices::open(&config).unwrap().into_agent().unwrap();
    let first =
        agent.waiter().wait(&"the world's observation", BOUND, || agent.try_observation()).unwrap();
    drop(first);
    kill_and_clean(world, &keeper);
    assert_noticed_gone(&agent, &named);
    drop((agent, keeper));
    assert_swept(&config, 0, "after the known world");
}

/// Starts `child_process` in `role`, waits until its ports exist, and SIGKILLs it.
fn spawn_and_kill(config: &RunConfig, role: &str) {
    let (mut child, _, _) = spawn_child(config, role);
    child.kill().unwrap();
    child.wait().unwrap();
}

#[test]
fn sigterm_makes_a_supervised_agent_leave_its_wait_cleanly() {
    let config = run("sigterm");
    let world = RunServices::create(&config).unwrap().into_world().unwrap();
    let (mut child, lines, seen) = spawn_child(&config, "supervised-agent");
    // Give it time to block in its wait; SIGTERM must cut the block short either way.
    std::thread::sleep(Duration::from_millis(50));
    let seen = terminate(&mut child, lines, seen);
    // It dropped its ports itself: nothing to clean.
    assert_eq!(world.peers().observation_subscribers, 0, "stdout:\n{seen}");
    assert_eq!(world.services().cleanup_dead_nodes(), 0);
}

/// SIGTERMs a child of [`spawn_child`] and checks that it left its wait or open with
/// `Terminated` and exited cleanly; returns all it printed (`seen` so far, then `lines`).
fn terminate(
    child: &mut Child,
    lines: std::io::Lines<std::io::BufReader<std::process::ChildStdout>>,
    mut seen: String,
) -> String {
    // SAFETY: signalling our own child by pid.
    assert_eq!(unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGTERM) }, 0);
    // Bounded: the wait or the open ends on SIGTERM at its next look, or at its time-out.
    for line in lines {
        seen.push_str(&line.unwrap());
        seen.push('\n');
    }
    let status = child.wait().unwrap();
    assert!(status.success(), "child {status}; stdout:\n{seen}");
    assert!(seen.contains("child-result Err(Terminated"), "stdout:\n{seen}");
    seen
}

/// A run no world serves, beside `config`'s.
fn unserved(config: &RunConfig) -> RunConfig {
    RunConfig { run_id: format!("{}-unserved", config.run_id), ..config.clone() }
}

/// A SIGTERM while an agent opens a run that no world serves (yet) ends the open with
/// `Terminated`. Before, it said `ServiceMissing`, "no world created ... within" the open's
/// whole time-out, a few milliseconds after the signal.
#[test]
fn sigterm_while_opening_a_run_says_terminated() {
    let config = run("sigterm-open");
    let _world = RunServices::create(&config).unwrap().into_world().unwrap();
    let (mut child, lines, seen) = spawn_child(&config, "supervised-opener");
    terminate(&mut child, lines, seen);
    let after = leftover_files(&unserved(&config).run_id).unwrap();
    assert!(after.is_empty(), "left behind by the open: {after:#?}");
}

/// The signals iceoryx2's default handler takes (0.10).
const ICEORYX2_SIGNALS: [libc::c_int; 13] = [
    libc::SIGINT,
    libc::SIGQUIT,
    libc::SIGABRT,
    libc::SIGUSR1,
    libc::SIGUSR2,
    libc::SIGTERM,
    libc::SIGCONT,
    libc::SIGTSTP,
    libc::SIGTTIN,
    libc::SIGTTOU,
    libc::SIGURG,
    libc::SIGVTALRM,
    libc::SIGPROF,
];

/// The signals a child in `role` catches and ignores once it made every port of a run and
/// waited on a listener: masks of `SigCgt` and `SigIgn` in its `/proc/self/status`.
fn signal_masks(role: &str) -> (u64, u64) {
    let config = run(role);
    let (mut child, lines, mut seen) = spawn_child(&config, role);
    for line in lines {
        seen.push_str(&line.unwrap());
        seen.push('\n');
    }
    assert!(child.wait().unwrap().success(), "stdout:\n{seen}");
    // The test harness may print its own words before a line of the child's.
    let mask = |name: &str| {
        let line = seen
            .lines()
            .find_map(|l| l.split_once(name).map(|(_, mask)| mask))
            .unwrap_or_else(|| panic!("no {name} line: {seen}"));
        u64::from_str_radix(line.trim(), 16).unwrap_or_else(|e| panic!("{name} {line}: {e}"))
    };
    (mask("SigCgt:"), mask("SigIgn:"))
}

/// iceoryx2 installs, by default, a handler that only latches SIGINT, SIGTERM, SIGTSTP and
/// ten more (docs/TRANSPORT.md, traps): Ctrl-Z would stop working and SIGTERM no longer
/// terminate. The transport disables it: a run's ports and waits change no signal unless the
/// process is supervised, which catches SIGTERM and ignores SIGINT, or interactive (an
/// attached agent), which catches both; and nothing else.
#[test]
fn ports_and_waits_take_only_the_signals_their_mode_names() {
    let bit = |signal: libc::c_int| 1u64 << (signal - 1);
    let iceoryx2_defaults = ICEORYX2_SIGNALS.into_iter().fold(0, |mask, signal| mask | bit(signal));
    let (caught, ignored) = signal_masks("untouched-signals");
    assert_eq!(caught & iceoryx2_defaults, 0, "caught: {caught:x}");
    assert_eq!(ignored & iceoryx2_defaults, 0, "ignored: {ignored:x}");
    let (caught, ignored) = signal_masks("supervised-signals");
    assert_eq!(caught & iceoryx2_defaults, bit(libc::SIGTERM), "caught: {caught:x}");
    assert_eq!(ignored & iceoryx2_defaults, bit(libc::SIGINT), "ignored: {ignored:x}");
    let (caught, ignored) = signal_masks("interactive-signals");
    let both = bit(libc::SIGINT) | bit(libc::SIGTERM);
    assert_eq!(caught & iceoryx2_defaults, both, "caught: {caught:x}");
    assert_eq!(ignored & iceoryx2_defaults, 0, "ignored: {ignored:x}");
}

#[test]
fn a_killed_world_is_swept() {
    let _sweeps = dead_nodes_lock();
    let config = run("killed");
    spawn_and_kill(&config, "world");
    assert!(
        !leftover_files(&config.run_id).unwrap().is_empty(),
        "a SIGKILL must leave files behind"
    );

    let sweep = sweep_stale_runs().unwrap();
    assert!(sweep.runs_cleaned.contains(&config.run_id), "{sweep:?}");
    let after = leftover_files(&config.run_id).unwrap();
    assert!(after.is_empty(), "left behind after the sweep: {after:#?}");
}

/// What an agent SIGKILLed while it created its ports was seen to leave (5 and 1 of 60 agents
/// killed 0 to 40 ms after they started): a half-made port tag in its node's directory (not
/// yet readable, so iceoryx2 does not list it), on which iceoryx2's clean-up of the node
/// fails after it removed the node's details, leaving what nothing removed; and an empty
/// event segment in /dev/shm. Made here by adding both to a killed world's files.
#[test]
fn what_a_node_killed_while_it_created_a_port_leaves_is_swept() {
    use std::os::unix::fs::PermissionsExt;
    let _sweeps = dead_nodes_lock();
    let config = run("halfmade");
    spawn_and_kill(&config, "world");
    let prefix = format!("flockstep.{}.", config.run_id);
    let node_dir = node_dir_of(&config);
    let half_made = |path: std::path::PathBuf, mode: u32| {
        std::fs::write(&path, b"").unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(mode)).unwrap();
        path
    };
    let tag = half_made(node_dir.join(format!("{prefix}1234.port_tag")), 0o600);
    let event = half_made(format!("/dev/shm/{prefix}abcd_1234.event_mgmt").into(), 0o200);

    assert_swept(&config, 1, "");
    assert!(!node_dir.exists() && !tag.exists() && !event.exists(), "{node_dir:?}");
}

/// The directory of the one node of `config`'s run (its process may be dead).
fn node_dir_of(config: &RunConfig) -> std::path::PathBuf {
    let files = leftover_files(&config.run_id).unwrap();
    files
        .iter()
        .filter_map(|file| file.parent().map(std::path::Path::to_path_buf))
        .find(|dir| dir.parent() == Some(iceoryx_root().join("nodes").as_path()))
        .unwrap_or_else(|| panic!("no node directory among {files:#?}"))
}

/// A dead node whose clean-up was itself killed after it removed, or emptied, the node's
/// directory and before the node's monitor is listed without details. It is swept all the
/// same; before, its monitor stayed for good, and every sweep counted it removed again.
/// Made by cleaning a killed world's node and putting its monitor back.
#[test]
fn a_node_whose_clean_up_was_killed_halfway_is_swept() {
    let _sweeps = dead_nodes_lock();
    for (test, emptied) in [("cutdir", false), ("cutfiles", true)] {
        let config = run(test);
        spawn_and_kill(&config, "world");
        let node_dir = node_dir_of(&config);
        let kept = tempfile::tempdir().unwrap();
        let mut monitor = leftover_files(&config.run_id).unwrap();
        monitor.retain(|file| file.to_string_lossy().contains(".node_monitor"));
        assert_eq!(monitor.len(), 3, "{test}: the monitor, its owner lock and its context");
        for file in &monitor {
            std::fs::copy(file, kept.path().join(file.file_name().unwrap())).unwrap();
        }
        assert_eq!(cleanup_run(&config.run_id).unwrap().dead_nodes, 1, "{test}");
        for file in &monitor {
            std::fs::copy(kept.path().join(file.file_name().unwrap()), file).unwrap();
        }
        if emptied {
            std::fs::create_dir(&node_dir).unwrap();
        }

        assert_swept(&config, 1, test);
        assert!(!node_dir.exists(), "{test}: the node's directory is left");
    }
}

/// A dead node that cannot be removed (here its details cannot be read, and its directory
/// holds complete files) counts as live, so its run keeps its node-id counter segment.
/// Before, it was counted as removed.
#[test]
fn a_dead_node_that_cannot_be_removed_counts_as_live() {
    use std::os::unix::fs::PermissionsExt;
    let _sweeps = dead_nodes_lock();
    let config = run("unreadable");
    spawn_and_kill(&config, "world");
    let node_dir = node_dir_of(&config);
    let details = std::fs::read_dir(&node_dir)
        .unwrap()
        .flatten()
        .map(|entry| entry.path())
        .find(|path| path.to_string_lossy().ends_with("node.details"))
        .expect("the killed world's node details");
    std::fs::set_permissions(&details, std::fs::Permissions::from_mode(0o600)).unwrap();
    std::fs::write(&details, b"not a node's details").unwrap();
    std::fs::set_permissions(&details, std::fs::Permissions::from_mode(0o400)).unwrap();

    let cleaned = cleanup_run(&config.run_id).unwrap();
    let left = leftover_files(&config.run_id).unwrap();
    for file in &left {
        std::fs::remove_file(file).unwrap();
    }
    // Emptied, the directory of a dead process is anyone's to remove (another test's clean-up
    // may have done it already).
    match std::fs::remove_dir(&node_dir) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => panic!("{}: {e}", node_dir.display()),
        _ => {}
    }
    assert_eq!((cleaned.dead_nodes, cleaned.live_nodes), (0, 1), "{cleaned:?}");
    let counter = |file: &&std::path::PathBuf| file.to_string_lossy().ends_with(".global_mgmt");
    assert!(left.iter().any(|file| counter(&file)), "the node-id counter went: {left:#?}");
}

/// A process killed between creating its node's directory and writing the node's details
/// into it leaves the directory empty, named by nothing but the node id (3 of 480 agents
/// killed 0 to 40 ms after they started). The clean-up of any run removes it once the
/// process that the id names is gone; one whose process lives (a node starting) is kept.
#[test]
fn an_empty_node_directory_is_removed_once_its_process_is_gone() {
    let _sweeps = dead_nodes_lock();
    let killed = run("emptydead");
    spawn_and_kill(&killed, "world");
    let dead_dir = node_dir_of(&killed);
    cleanup_run(&killed.run_id).unwrap();
    std::fs::create_dir(&dead_dir).unwrap();
    let living = run("emptyalive");
    let world = RunServices::create(&living).unwrap();
    let own_id: u128 = node_dir_of(&living).file_name().unwrap().to_str().unwrap().parse().unwrap();
    // The same process and counter, a second later: as iceoryx2 would name it.
    let live_dir = iceoryx_root().join("nodes").join((own_id + 1).to_string());
    std::fs::create_dir(&live_dir).unwrap();
    let _remove = RemoveDir(live_dir.clone());

    let cleaned = cleanup_run(&killed.run_id).unwrap();
    assert!(!dead_dir.exists(), "the killed process's directory was kept: {cleaned:?}");
    assert!(live_dir.exists(), "the directory of a living process was removed");
    drop(world);
}

/// An agent killed between writing its node's details and completing the node's monitor (2
/// of about 500 agents killed 0 to 40 ms after they started: one before the monitor, one
/// while it was made) leaves a node that nothing lists. The sweep finds the run by it and
/// removes it; a node still starting, whose process holds its details open, is kept. Made
/// here by hand, as iceoryx2 lays them out.
#[test]
fn nodes_that_died_as_they_started_are_swept_and_one_starting_is_kept() {
    use std::os::unix::fs::PermissionsExt;
    let _sweeps = dead_nodes_lock();
    let config = run("diedstarting");
    cleanup_run(&config.run_id).expect("this user's iceoryx2 root");
    let nodes = iceoryx_root().join("nodes");
    let prefix = format!("flockstep.{}.", config.run_id);
    // Node ids of this test process: a failed run's directories do not meet the next run's.
    let node = |last_digit: u32| {
        let node_id = format!("4242{:010}{last_digit}", std::process::id());
        let dir = nodes.join(&node_id);
        std::fs::create_dir_all(&dir).unwrap();
        let details = dir.join(format!("{prefix}node.details"));
        std::fs::write(&details, b"written, not yet made read-only").unwrap();
        (dir, details, node_id)
    };
    let (before_monitor, _, _) = node(1);
    let (making_monitor, _, node_id) = node(2);
    let monitor: Vec<_> = ["", "_owner_lock", "_context"]
        .iter()
        .map(|suffix| nodes.join(format!("{prefix}{node_id}.node_monitor{suffix}")))
        .collect();
    for file in &monitor {
        std::fs::write(file, b"").unwrap();
        std::fs::set_permissions(file, std::fs::Permissions::from_mode(0o200)).unwrap();
    }
    let (starting, details, _) = node(3);
    let held = std::fs::File::open(&details).unwrap();

    let sweep = sweep_stale_runs().unwrap();
    assert!(!before_monitor.exists(), "died before its monitor, left: {sweep:?}");
    let left: Vec<_> = monitor.iter().filter(|file| file.exists()).collect();
    assert!(!making_monitor.exists() && left.is_empty(), "died making its monitor, left {left:?}");
    assert!(starting.exists(), "the directory of a node still starting was removed");
    drop(held);
    assert_swept(&config, 1, "");
    assert!(!starting.exists(), "the node that had been starting is left");
}

/// A process killed between creating a segment and sizing it leaves an empty one; iceoryx2,
/// removing the dead process's ports, waited on it for good (the world hung, and so did every
/// later start-up sweep). Made here by emptying a segment of a killed run; the clean-up runs
/// on a thread so that a hang fails the test instead of stopping it.
#[test]
fn an_empty_segment_of_a_killed_process_does_not_hang_the_clean_up() {
    let _sweeps = dead_nodes_lock();
    let config = run("emptyseg");
    let (mut world, _, _) = spawn_child(&config, "world");
    spawn_and_kill(&config, "agent");
    world.kill().unwrap();
    world.wait().unwrap();
    let segments = leftover_files(&config.run_id).unwrap();
    let connection = segments
        .iter()
        .find(|path| path.to_string_lossy().ends_with(".connection"))
        .unwrap_or_else(|| panic!("no connection segment among {segments:#?}"));
    std::fs::OpenOptions::new().write(true).open(connection).unwrap().set_len(0).unwrap();

    let (done, cleaned) = std::sync::mpsc::channel();
    let run_id = config.run_id.clone();
    std::thread::spawn(move || done.send(cleanup_run(&run_id)));
    let cleaned = cleaned.recv_timeout(BOUND * 2).expect("the clean-up hung").unwrap();
    assert_eq!((cleaned.dead_nodes, cleaned.live_nodes), (2, 0), "{cleaned:?}");
    let after = leftover_files(&config.run_id).unwrap();
    assert!(after.is_empty(), "left behind after clean-up: {after:#?}");
}

/// What a process killed as it created a port leaves before iceoryx2 recorded the port is
/// named by nothing but the run's prefix: a listener's segment and socket (1 of about 250
/// agents killed 0 to 40 ms after they started), a lone socket (a listener killed as it was
/// dropped, between its segment and its socket, leaves one) and a `*.connection` segment
/// (1 each in about 400 more). Once no node of the run is left they are removed; a listener
/// of a run of the same id starting meanwhile, whose segment is mapped and whose socket is
/// bound, keeps both. So is a finished service description whose service is gone, unless a
/// process holds it open. Made here by hand, as iceoryx2 lays them out.
#[test]
fn files_of_a_run_with_no_node_that_no_process_uses_are_swept() {
    let _sweeps = dead_nodes_lock();
    let config = run("unused");
    let prefix = format!("flockstep.{}.", config.run_id);
    let segment = |name: &str| {
        let segment = std::path::PathBuf::from(format!("/dev/shm/{prefix}{name}"));
        std::fs::write(&segment, [7u8; 64]).unwrap();
        segment
    };
    let listener = |id: &str| {
        let socket = iceoryx_root().join(format!("{prefix}{id}.event"));
        let bound = std::os::unix::net::UnixDatagram::bind(&socket).unwrap();
        (segment(&format!("{id}.event_mgmt")), bound, socket)
    };
    let (killed_segment, killed_socket, killed_socket_path) = listener("1111");
    drop(killed_socket);
    let (dropped_segment, dropped_socket, dropped_socket_path) = listener("3333");
    std::fs::remove_file(&dropped_segment).unwrap();
    drop(dropped_socket);
    let connection = segment("abcd_1111_2222.connection");
    let (live_segment, live_socket, live_socket_path) = listener("2222");
    let mapping = Mapping::of(&live_segment);
    // Finished (read-only) descriptions: one whose service is gone, one a process uses.
    let services = iceoryx_root().join("services");
    // As iceoryx2 makes it, on a machine where no service was made yet.
    std::os::unix::fs::DirBuilderExt::mode(std::fs::DirBuilder::new().recursive(true), 0o750)
        .create(&services)
        .unwrap();
    let description = |hash: &str| {
        use std::os::unix::fs::PermissionsExt;
        let path = services.join(format!("{prefix}{hash}.service"));
        std::fs::write(&path, b"a service's description").unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o400)).unwrap();
        path
    };
    let orphaned = description("5555");
    let used = description("6666");
    let held_open = std::fs::File::open(&used).unwrap();

    let cleaned = cleanup_run(&config.run_id).unwrap();
    assert_eq!((cleaned.live_nodes, cleaned.files), (0, 5), "{cleaned:?}");
    assert!(!killed_segment.exists() && !killed_socket_path.exists(), "the killed listener's");
    assert!(!dropped_socket_path.exists(), "the socket of a listener killed as it was dropped");
    assert!(!connection.exists(), "the connection no process maps");
    assert!(!orphaned.exists(), "the description no process holds");
    assert!(live_segment.exists() && live_socket_path.exists(), "a live listener's were removed");
    assert!(used.exists(), "a description a process holds was removed");
    drop((mapping, live_socket, held_open));
    cleanup_run(&config.run_id).unwrap();
    let after = leftover_files(&config.run_id).unwrap();
    assert!(after.is_empty(), "left behind after clean-up: {after:#?}");
}

/// A service description its creator was killed making stays writable, and iceoryx2 takes it
/// for a service still being created: the next create of the service failed as if it
/// existed (3 of 10 worlds killed as their first service appeared). The clean-up removes
/// one that no process has open, even while the run has live nodes; one held open (as a
/// creator holds it while it makes it) and a live world's finished ones are kept.
#[test]
fn a_service_description_left_in_creation_is_removed() {
    use std::os::unix::fs::PermissionsExt;
    let _sweeps = dead_nodes_lock();
    let config = run("in-creation");
    let world = RunServices::create(&config).unwrap();
    let services = iceoryx_root().join("services");
    let prefix = format!("flockstep.{}.", config.run_id);
    let writable = |hash: &str| {
        let path = services.join(format!("{prefix}{hash}.service"));
        std::fs::write(&path, b"a description being written").unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).unwrap();
        path
    };
    let left = writable("5555");
    let being_made = writable("6666");
    let held_open = std::fs::File::open(&being_made).unwrap();
    let finished = || {
        leftover_files(&config.run_id)
            .unwrap()
            .into_iter()
            .filter(|path| path.starts_with(&services) && path != &left && path != &being_made)
    };
    let finished_before = finished().count();
    assert!(finished_before > 0, "the world's services have no descriptions");

    let cleaned = cleanup_run(&config.run_id).unwrap();
    assert_eq!((cleaned.live_nodes, cleaned.files), (1, 1), "{cleaned:?}");
    assert!(!left.exists(), "a description left in creation was kept");
    assert!(being_made.exists(), "a description held open was removed");
    assert_eq!(finished().count(), finished_before, "a live service's description was removed");
    drop(held_open);
    std::fs::remove_file(&being_made).unwrap();
    drop(world);
    let after = leftover_files(&config.run_id).unwrap();
    assert!(after.is_empty(), "left behind: {after:#?}");
}

/// A file mapped into this process, as a listener maps its segment, with no descriptor left
/// open; unmapped when dropped.
struct Mapping(*mut libc::c_void);

impl Mapping {
    fn of(path: &std::path::Path) -> Mapping {
        use std::os::fd::AsRawFd;
        let file = std::fs::OpenOptions::new().read(true).write(true).open(path).unwrap();
        // SAFETY: a fresh shared mapping of a 64-byte file this test made; nothing reads it.
        let at = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                64,
                libc::PROT_READ,
                libc::MAP_SHARED,
                file.as_raw_fd(),
                0,
            )
        };
        assert_ne!(at, libc::MAP_FAILED, "mapping {}", path.display());
        Mapping(at)
    }
}

impl Drop for Mapping {
    fn drop(&mut self) {
        // SAFETY: the mapping made in `of`, unmapped once.
        unsafe { libc::munmap(self.0, 64) };
    }
}

/// Removes a directory when dropped, so a failing test leaves nothing in /dev/shm.
struct RemoveDir(std::path::PathBuf);

impl Drop for RemoveDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir(&self.0);
    }
}

/// An old run whose files cannot be removed (as another user's are; here a directory where
/// iceoryx2 keeps its node-id counter, which unlink refuses even to root) is reported and
/// skipped: the sweep still cleans the runs after it. Before, it failed the sweep, and with
/// it every later run over shared memory.
#[test]
fn a_run_whose_files_cannot_be_removed_does_not_stop_the_sweep() {
    let _sweeps = dead_nodes_lock();
    // Sorted before the stale run, so the sweep meets it first.
    let stuck = run("sweepa");
    let stale = run("sweepb");
    let counter = format!("/dev/shm/flockstep.{}.stuck.global_mgmt", stuck.run_id);
    std::fs::create_dir(&counter).unwrap();
    let _remove = RemoveDir(counter.into());
    spawn_and_kill(&stale, "world");
    assert!(!leftover_files(&stale.run_id).unwrap().is_empty(), "a SIGKILL leaves files");

    let sweep = sweep_stale_runs().expect("the sweep goes on past a run it cannot clean");
    let failed = sweep.failed.iter().find(|(id, _)| *id == stuck.run_id);
    let (_, error) = failed.unwrap_or_else(|| panic!("the stuck run is not reported: {sweep:?}"));
    assert!(error.contains("removing /dev/shm/") && error.contains("stuck"), "{error}");
    let left = leftover_files(&stale.run_id).unwrap();
    assert!(left.is_empty(), "the run after the stuck one was not cleaned: {left:#?}");
    assert!(cleanup_run(&stuck.run_id).is_err(), "cleaning the stuck run itself still fails");
}

#[test]
fn the_world_removes_a_killed_agent() {
    let _sweeps = dead_nodes_lock();
    let config = run("deadagent");
    let world = RunServices::create(&config).unwrap().into_world().unwrap();
    spawn_and_kill(&config, "agent");
    assert_eq!(
        world.peers().observation_subscribers,
        1,
        "the dead agent's ports stay until cleaned"
    );
    assert_eq!(world.services().cleanup_dead_nodes(), 1);
    let peers = world.peers();
    assert_eq!(
        (peers.observation_subscribers, peers.action_publishers, peers.agent_listeners),
        (0, 0, 0)
    );
}

#[test]
fn episode_records_outlive_the_world_that_sent_them() {
    let config = run("outlive");
    let mut world = RunServices::create(&config).unwrap().into_world().unwrap();
    let supervisor = RunServices::open(&config).unwrap().into_supervisor().unwrap();
    let sent = flockstep_proto::transport::EPISODE_BUFFER as u64;
    for episode in 0..sent {
        world.queue_episode(&EpisodeReport { episode, ..EpisodeReport::default() }).unwrap();
    }
    world.flush_episodes().unwrap();
    drop(world);
    let mut received = Vec::new();
    while let Some(report) = try_episode(&supervisor).unwrap() {
        received.push(report.episode);
    }
    assert_eq!(received, (0..sent).collect::<Vec<_>>());
}

/// The supervisor follows its processes through the membership: each change goes out at
/// once with the records queued before it, wakes the supervisor, and is told after those
/// records; a batch that changes nothing tells no membership.
#[test]
fn a_change_of_membership_goes_out_at_once_after_the_records_before_it() {
    let config = run("membership");
    let mut world = RunServices::create(&config).unwrap().into_world().unwrap();
    let supervisor = RunServices::open(&config).unwrap().into_supervisor().unwrap();
    let mut admitted = Membership { live: 0b11, ..Membership::default() };
    admitted.pids[..2].copy_from_slice(&[101, 102]);
    let dropped = Membership { live: 0b01, pids: admitted.pids };
    world.queue_episode(&EpisodeReport { episode: 0, ..EpisodeReport::default() }).unwrap();
    world.set_membership(&admitted).unwrap();
    world.queue_episode(&EpisodeReport { episode: 1, ..EpisodeReport::default() }).unwrap();
    world.set_membership(&dropped).unwrap();
    world.queue_episode(&EpisodeReport { episode: 2, ..EpisodeReport::default() }).unwrap();
    world.flush_episodes().unwrap();
    // Woken at once by the first change, not at the end of the sleep.
    let long = Duration::from_secs(60);
    let started = std::time::Instant::now();
    supervisor.waiter().sleep(long).unwrap();
    assert!(started.elapsed() < long / 4, "the membership did not wake the supervisor");
    let mut told = Vec::new();
    while let Some(next) = supervisor.try_next().unwrap() {
        told.push(next);
    }
    let episode = |episode| FromWorld::Episode(EpisodeReport { episode, ..Default::default() });
    assert_eq!(
        told,
        [
            episode(0),
            FromWorld::Membership(admitted),
            episode(1),
            FromWorld::Membership(dropped),
            episode(2)
        ]
    );
}

#[test]
fn queued_episode_records_wait_for_a_full_batch_or_a_flush() {
    let config = run("batch");
    let mut world = RunServices::create(&config).unwrap().into_world().unwrap();
    let supervisor = RunServices::open(&config).unwrap().into_supervisor().unwrap();
    let queued = flockstep_proto::EPISODE_BATCH as u64 + 3;
    for episode in 0..queued {
        world.queue_episode(&EpisodeReport { episode, ..EpisodeReport::default() }).unwrap();
    }
    let mut received = Vec::new();
    while let Some(report) = try_episode(&supervisor).unwrap() {
        received.push(report.episode);
    }
    let full: Vec<u64> = (0..flockstep_proto::EPISODE_BATCH as u64).collect();
    assert_eq!(received, full, "only the full batch went out");
    world.flush_episodes().unwrap();
    while let Some(report) = try_episode(&supervisor).unwrap() {
        received.push(report.episode);
    }
    assert_eq!(received, (0..queued).collect::<Vec<_>>(), "the flush sent the rest, in order");
}

#[test]
fn a_full_episode_buffer_fails_after_the_report_timeout_instead_of_dropping() {
    let mut config = run("stalled");
    config.report_timeout = Duration::from_millis(50);
    let mut world = RunServices::create(&config).unwrap().into_world().unwrap();
    let _idle_supervisor = RunServices::open(&config).unwrap().into_supervisor().unwrap();
    let report = EpisodeReport::default();
    for _ in 0..flockstep_proto::transport::EPISODE_BUFFER {
        world.queue_episode(&report).unwrap();
    }
    world.queue_episode(&report).unwrap();
    let error = world.flush_episodes().unwrap_err();
    assert!(matches!(error, TransportError::ReportsStalled { .. }), "{error}");
}

/// A transport error carries its cause in its message only: as a `source` too, reports that
/// follow the chain (`{:#}`) printed it twice ("Permission denied (os error 13): Permission
/// denied (os error 13)").
#[test]
fn an_error_says_its_cause_once() {
    let cause = std::io::Error::from_raw_os_error(libc::EACCES);
    let error = TransportError::Io { what: "listing /tmp/flockstep-0".into(), cause };
    assert!(std::error::Error::source(&error).is_none());
    assert_eq!(
        error.to_string(),
        "listing /tmp/flockstep-0 failed: Permission denied (os error 13)"
    );
}
