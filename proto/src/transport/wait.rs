//! The barrier's waiting strategy. On 2 cores a run has more processes than cores, so a
//! waiter that spins keeps the very peer it waits for off the CPU; one that blocks at once
//! pays a kernel wake-up (an inter-processor interrupt, in a VM also an exit) every round.
//! Polling with `yield_now` in between, then blocking, was measured best by
//! `benches/barrier.rs`; `docs/TRANSPORT.md` has the numbers.

use super::{termination_requested, Ipc, TransportError};
use iceoryx2::port::listener::{Listener, ListenerWaitError};
use std::cell::Cell;
use std::fmt::Display;
use std::time::{Duration, Instant};

/// The shortest block on the listener. iceoryx2 hands the socket its timeout in whole
/// microseconds, and a timeout of 0 there means none: a block of less than a microsecond,
/// such as a wait's last one before its deadline, would last until a wake-up came, which a
/// silent peer never sends.
const SHORTEST_BLOCK: Duration = Duration::from_micros(1);

/// The phases of a wait, tuned on a 2-core machine by `benches/barrier.rs`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WaitPolicy {
    /// Polls with only a CPU pause in between. Pays off only with more idle cores than
    /// processes; on 2 cores it keeps the peer that would answer off the CPU.
    pub spins: u32,
    /// Polls with `yield_now` in between: hands the core to a peer that is ready to answer,
    /// and costs a mere syscall when none is. No clock is read while they last.
    pub yields: u32,
    /// After the counted yields the waiter goes on yielding until this long after the wait
    /// began (or until its deadline, if sooner), reading the clock at each poll. A wait that
    /// outlasts the counted yields was held up (a peer preempted by the host or by another
    /// process for a few µs); blocking then would add a kernel wake-up to the hold-up
    /// (those rounds took 49 to 103 µs).
    pub yield_for: Duration,
    /// Longest single block on the listener; bounds how late a missed wake-up or a deadline
    /// can be noticed.
    pub slice: Duration,
    /// How long the waiter blocks at once, without spinning or yielding, after
    /// [`STALLS_TO_BACK_OFF`] waits within [`STALL_WINDOW`] whose yielding lasted over
    /// [`STALLED_YIELDING`]: the core went to a process outside the run for whole time
    /// slices, so the machine has more runnable processes than cores (one such wait may be
    /// the host's doing). A yielding peer is then queued behind that process, while a
    /// blocked one is woken ahead of it: with two barriers and two CPU hogs on 2 cores,
    /// yielding made about 500 rounds/s and blocking 13 000 to 14 000 (docs/TRANSPORT.md).
    /// Zero never backs off.
    pub backoff: Duration,
}

/// Yielding that lasts longer than this in one wait means a process outside the run took
/// the core: a round's own work is µs, and the yielding is bounded by `yield_for` unless a
/// yield itself is held up.
pub const STALLED_YIELDING: Duration = Duration::from_millis(1);

/// Stalled waits within [`STALL_WINDOW`] that make a waiter back off from yielding. On the
/// 2-vCPU VM measured a single one happened now and then without any foreign load (the host
/// preempting a vCPU), and backing off on it cost unloaded runs rounds. Under foreign load
/// most waits still end at once (p50 13 µs) but one in a few stalls for a time slice.
pub const STALLS_TO_BACK_OFF: u32 = 3;

/// See [`STALLS_TO_BACK_OFF`].
pub const STALL_WINDOW: Duration = Duration::from_millis(50);

/// The most one look at the clock counts against a wait's deadline beyond the block before
/// it. Later than that, the process did not run in between: stopped (SIGSTOP, or Ctrl-Z,
/// which the supervisor passes on to the whole run) or starved; the rest of the gap does
/// not count. So a paused run resumes where it was instead of every process presuming its
/// peers dead (they were paused too, and get the rest of their time to answer), however
/// short the pause. A process that runs while its peer is stopped still sees the peer
/// silent, and a waiter still times out, if late, when every look comes late: each counts
/// its block and this much. Time slices lost to other processes, a few milliseconds, stay
/// below it even on a loaded machine.
pub const PAUSE_GAP: Duration = Duration::from_millis(100);

impl WaitPolicy {
    /// Blocks on the event at once: the least CPU, the most wake-up latency.
    pub const BLOCK: WaitPolicy = WaitPolicy {
        spins: 0,
        yields: 0,
        yield_for: Duration::ZERO,
        slice: Duration::from_millis(10),
        backoff: Duration::ZERO,
    };
}

impl Default for WaitPolicy {
    /// Measured on 2 cores with 2 and 8 agents: 7 to 13 and about 3 times the rounds/s of
    /// blocking at once. The yields must outlast the work of a round, or the waiter blocks
    /// and pays a wake-up of tens of µs: 16 (about 4 µs when nothing else is runnable) did
    /// at 1 trial but not at 4, where 32 made 4-trial runs 18% faster and left 8 agents
    /// as they were. Even so 0.6 to 1.6% of the rounds had a wait that blocked after a
    /// hold-up of a few µs, and those rounds took 3 to 12% of the run's time; yielding for
    /// up to 200 µs cut them to 0.01 to 0.05% of the rounds (`docs/PERFORMANCE.md`, "Yielding
    /// through hold-ups").
    fn default() -> Self {
        WaitPolicy {
            spins: 0,
            yields: 32,
            yield_for: Duration::from_micros(YIELD_FOR_US),
            slice: Duration::from_millis(10),
            backoff: Duration::from_millis(BACKOFF_MS),
        }
    }
}

/// How long [`WaitPolicy::default`] yields before it blocks.
const YIELD_FOR_US: u64 = 200;

/// How long [`WaitPolicy::default`] blocks at once after stalled yielding: long enough that
/// the one stalled wait (a time slice, a few ms) that ends each backoff costs little, short
/// enough that a run soon yields again once the machine is free.
const BACKOFF_MS: u64 = 100;

/// Waits on one wake-up event: spin, then yield, then block in slices, until `poll` has
/// something or the deadline passes. Checks the SIGTERM latch on entry and after every block.
pub struct Waiter {
    listener: Listener<Ipc>,
    policy: WaitPolicy,
    /// Stalled waits since `first_stall`, which began the current [`STALL_WINDOW`].
    stalls: Cell<u32>,
    first_stall: Cell<Option<Instant>>,
    /// Set by stalled yielding: until then every wait blocks at once (`policy.backoff`).
    /// Cleared by the first wait after it.
    block_until: Cell<Option<Instant>>,
    run_id: String,
    service: String,
}

impl Waiter {
    pub(super) fn new(
        listener: Listener<Ipc>,
        policy: WaitPolicy,
        run_id: &str,
        service: &str,
    ) -> Waiter {
        Waiter {
            listener,
            policy,
            stalls: Cell::new(0),
            first_stall: Cell::new(None),
            block_until: Cell::new(None),
            run_id: run_id.into(),
            service: service.into(),
        }
    }

    /// Calls `poll` until it returns `Some`, for at most `timeout`. `what` names the awaited
    /// thing in the error (pass `&format_args!(..)`: it is only formatted on failure).
    ///
    /// No wake-up is lost: the peer publishes before it notifies, and a notification that
    /// arrives between a failed poll and the block stays pending, so the block returns at once.
    pub fn wait<T>(
        &self,
        what: &dyn Display,
        timeout: Duration,
        mut poll: impl FnMut() -> Result<Option<T>, TransportError>,
    ) -> Result<T, TransportError> {
        let start = Instant::now();
        self.check_termination(what)?;
        if let Some(until) = self.block_until.get() {
            if start < until {
                return self.block(what, timeout, start, Duration::ZERO, poll);
            }
            self.block_until.set(None);
        }
        for _ in 0..self.policy.spins {
            if let Some(found) = poll()? {
                return Ok(found);
            }
            std::hint::spin_loop();
        }
        // The counted yields first, without a clock; then on until `yield_for` has passed.
        let yield_until = self.policy.yield_for.min(timeout);
        for yielded in 0u64.. {
            if let Some(found) = poll()? {
                if yielded > 0 {
                    self.note_yielding(start, start.elapsed());
                }
                return Ok(found);
            }
            if yielded >= u64::from(self.policy.yields) {
                let yielding = start.elapsed();
                if yielding >= yield_until {
                    self.note_yielding(start, yielding);
                    break;
                }
            }
            std::thread::yield_now();
        }
        self.block(what, timeout, start, yield_until, poll)
    }

    /// Counts the wait begun at `start` as stalled if its `yielding` was, and backs off from
    /// yielding after [`STALLS_TO_BACK_OFF`] stalled ones within a [`STALL_WINDOW`].
    fn note_yielding(&self, start: Instant, yielding: Duration) {
        if yielding <= STALLED_YIELDING || self.policy.backoff.is_zero() {
            return;
        }
        let in_window = self.first_stall.get().is_some_and(|first| start - first < STALL_WINDOW);
        if !in_window {
            self.first_stall.set(Some(start));
            self.stalls.set(0);
        }
        self.stalls.set(self.stalls.get() + 1);
        if self.stalls.get() >= STALLS_TO_BACK_OFF {
            self.first_stall.set(None);
            self.block_until.set(Some(start + yielding + self.policy.backoff));
        }
    }

    /// The blocking phase of [`Self::wait`]: polls, then blocks on the listener in slices,
    /// until `poll` has something or `timeout` (from `start`, less the time the process was
    /// paused, see [`PAUSE_GAP`]) passes. Before it, the wait yielded for up to `yielded`.
    fn block<T>(
        &self,
        what: &dyn Display,
        timeout: Duration,
        start: Instant,
        yielded: Duration,
        mut poll: impl FnMut() -> Result<Option<T>, TransportError>,
    ) -> Result<T, TransportError> {
        let mut last_look = start;
        // What the time since the last look was spent on: the yielding before the first,
        // then at most one slice slept.
        let mut spent = yielded;
        let mut paused = Duration::ZERO;
        loop {
            if let Some(found) = poll()? {
                return Ok(found);
            }
            let now = Instant::now();
            paused += (now - last_look).saturating_sub(spent + PAUSE_GAP);
            (last_look, spent) = (now, self.policy.slice);
            let waited = (now - start).saturating_sub(paused);
            if waited >= timeout {
                return Err(TransportError::Timeout {
                    run: self.run_id.clone(),
                    service: self.service.clone(),
                    what: what.to_string(),
                    waited,
                });
            }
            self.sleep(self.policy.slice.min(timeout - waited))?;
            self.check_termination(what)?;
        }
    }

    /// Blocks until a wake-up arrives or `timeout` passes, polling nothing: for a reader that
    /// drains on its own schedule (the supervisor) instead of answering at once. A wake-up
    /// sent while it was not blocked ends the next call at once. A timeout under a
    /// microsecond blocks for one (`SHORTEST_BLOCK`).
    pub fn sleep(&self, timeout: Duration) -> Result<(), TransportError> {
        match self.listener.timed_wait(|_| {}, timeout.max(SHORTEST_BLOCK)) {
            // A signal cut the block short: the caller re-checks what it waits for.
            Ok(_) | Err(ListenerWaitError::InterruptSignal) => Ok(()),
            Err(e) => Err(TransportError::Port {
                run: self.run_id.clone(),
                service: self.service.clone(),
                op: "waiting on the listener",
                cause: Box::new(e),
            }),
        }
    }

    /// For the polls of this waiter's next wait: see [`Overdue`]. Reads no clock: a backoff
    /// that has just run out still counts as one (the wait then reads the clock at each poll
    /// while it yields, once).
    pub fn overdue_after(&self, after: Duration, every: Duration) -> Overdue {
        let backing_off = self.block_until.get().is_some();
        let quick_polls = if backing_off { 0 } else { self.policy.spins + self.policy.yields };
        Overdue { quick_polls, polls: 0, since: None, after, every, last: None }
    }

    fn check_termination(&self, what: &dyn Display) -> Result<(), TransportError> {
        if termination_requested() {
            return Err(TransportError::Terminated {
                run: self.run_id.clone(),
                what: what.to_string(),
            });
        }
        Ok(())
    }
}

/// Tells a wait's poll when to make a check too dear for every poll: whether a silent peer
/// is gone (a listing of the run's nodes, 0.3 ms at 2 UAVs and 2.2 ms at 32, where a round
/// takes µs). First once the wait has gone on for `after`, then at most once per `every`:
/// looking at every poll, 32 waiting agents kept both cores busy while one agent was
/// stopped, and agents stopped for less than their deadline were dropped. The waiter's
/// counted polls come first and take microseconds in all, so none of them reads the clock
/// here either (a backing-off waiter makes none); each later one reads it, as the waiter
/// itself does then.
#[derive(Debug)]
pub struct Overdue {
    quick_polls: u32,
    polls: u32,
    since: Option<Instant>,
    after: Duration,
    every: Duration,
    last: Option<Instant>,
}

impl Overdue {
    /// Counts a poll that found nothing: true once the polls have gone on for `after` since
    /// the counted ones ended, and `every` since it last said true.
    pub fn check(&mut self) -> bool {
        self.polls = self.polls.saturating_add(1);
        if self.polls <= self.quick_polls {
            return false;
        }
        let now = Instant::now();
        let since = *self.since.get_or_insert(now);
        if now - since <= self.after || self.last.is_some_and(|last| now - last < self.every) {
            return false;
        }
        self.last = Some(now);
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::transport::{RunConfig, RunServices, SignalMode, WorldPorts};

    /// The ports of a world in a run of its own, waiting with `policy`. Nothing ever
    /// notifies its listener, so a wait that blocks sleeps until its slice or deadline ends.
    fn world_waiting_with(tag: &str, policy: WaitPolicy) -> WorldPorts {
        let mut run =
            RunConfig::new(format!("wait-{tag}-{}", std::process::id()), SignalMode::Untouched);
        run.wait = policy;
        RunServices::create(&run).and_then(RunServices::into_world).expect("a run of its own")
    }

    #[test]
    fn an_answer_held_up_past_the_counted_yields_is_found_by_yielding() {
        let long = Duration::from_secs(60);
        let policy = WaitPolicy { yields: 2, yield_for: long, slice: long, ..WaitPolicy::BLOCK };
        let ports = world_waiting_with("held-up", policy);
        let mut polls = 0u32;
        // Had the waiter blocked after its 2 yields, it would have slept to the deadline
        // and timed out with fewer than 5 polls.
        let found = ports.waiter().wait(&"a held-up answer", Duration::from_secs(5), || {
            polls += 1;
            Ok((polls == 1000).then_some(polls))
        });
        assert_eq!(found.expect("found while yielding"), 1000);
    }

    #[test]
    fn a_waiter_blocks_once_its_yields_and_yield_time_are_spent() {
        let (yields, yield_for) = (3, Duration::from_millis(1));
        // One block lasts to the deadline: nothing notifies.
        let policy =
            WaitPolicy { yields, yield_for, slice: Duration::from_secs(60), ..WaitPolicy::BLOCK };
        let ports = world_waiting_with("spent", policy);
        let start = Instant::now();
        let mut polls = Vec::new();
        let waited = ports.waiter().wait(&"nothing", Duration::from_millis(100), || {
            polls.push(start.elapsed());
            Ok(None::<()>)
        });
        assert!(
            matches!(waited, Err(TransportError::Timeout { .. })),
            "nothing to find ends in a timeout: {waited:?}"
        );
        // The waiter blocked once: one gap between polls spans most of the deadline. A
        // waiter that went on yielding polls at least once a time slice (a few ms) even on
        // the busiest machine. How many polls come after that gap is not asserted: the
        // listener's timeout is counted in kernel ticks (4 ms at HZ=250) and may end up to
        // one tick early, and the waiter then blocks again for the rest.
        let (block_began, longest_gap) = polls
            .windows(2)
            .map(|pair| (pair[0], pair[1] - pair[0]))
            .max_by_key(|&(_, gap)| gap)
            .expect("more than one poll");
        assert!(longest_gap >= Duration::from_millis(50), "polls {polls:?}: no long block");
        // It blocked only after its counted yields and its yield time.
        let polls_before = polls.iter().filter(|&&at| at <= block_began).count();
        assert!(polls_before as u32 > yields, "blocked after {polls_before} polls: {polls:?}");
        assert!(block_began >= yield_for, "blocked {block_began:?} into the wait: {polls:?}");
    }

    #[test]
    fn the_deadline_ends_the_yielding_too() {
        let long = Duration::from_secs(60);
        let policy = WaitPolicy { yield_for: long, slice: long, ..WaitPolicy::BLOCK };
        let ports = world_waiting_with("deadline", policy);
        match ports.waiter().wait(&"nothing", Duration::from_millis(50), || Ok(None::<()>)) {
            // Measured by the waiter itself: yielding on to `yield_for` would report 60 s.
            Err(TransportError::Timeout { waited, .. }) => {
                assert!(waited < Duration::from_secs(30), "timed out only after {waited:?}")
            }
            other => panic!("nothing to find ends in a timeout: {other:?}"),
        }
    }

    /// The yielding before the block is the wait's own time, not a pause: a wait that yields
    /// for most of its timeout still ends at its deadline. Before, all of that yielding
    /// beyond one slice and [`PAUSE_GAP`] went uncounted, and the wait went on about as long
    /// again.
    #[test]
    fn a_wait_that_yields_for_most_of_its_timeout_ends_at_its_deadline() {
        let yield_for = Duration::from_secs(1);
        let policy = WaitPolicy { yield_for, ..WaitPolicy::BLOCK };
        let ports = world_waiting_with("long-yield", policy);
        let start = Instant::now();
        let waited = ports.waiter().wait(&"nothing", yield_for + PAUSE_GAP, || Ok(None::<()>));
        assert!(matches!(waited, Err(TransportError::Timeout { .. })), "{waited:?}");
        // Ending about 1.1 s in; it went on to about 2 s.
        let took = start.elapsed();
        assert!(took < yield_for + PAUSE_GAP * 5, "a 1.1 s wait took {took:?}");
    }

    /// A process stopped in the middle of a wait (here: a poll that takes as long, as the
    /// look after a SIGSTOP does) has at most [`PAUSE_GAP`] of that time counted against the
    /// deadline, so a pause longer than the deadline does not end the wait.
    #[test]
    fn time_the_waiter_was_stopped_does_not_count_against_its_deadline() {
        let ports = world_waiting_with("paused", WaitPolicy::BLOCK);
        let mut polls = 0u32;
        let timeout = Duration::from_millis(300);
        let found = ports.waiter().wait(&"an answer after a pause", timeout, || {
            polls += 1;
            if polls == 2 {
                std::thread::sleep(timeout * 2);
            }
            Ok((polls == 4).then_some(polls))
        });
        assert_eq!(found.expect("the pause is not waiting"), 4);
    }

    /// A waiter all of whose looks come late (starved, or a poll that blocks) still times
    /// out: each look counts its block and [`PAUSE_GAP`], so the deadline is reached within
    /// a bounded number of looks.
    #[test]
    fn a_waiter_whose_every_look_comes_late_still_times_out() {
        let ports = world_waiting_with("late", WaitPolicy::BLOCK);
        let mut polls = 0u32;
        let waited = ports.waiter().wait(&"nothing", Duration::from_millis(250), || {
            polls += 1;
            std::thread::sleep(PAUSE_GAP * 3);
            Ok(None::<()>)
        });
        assert!(matches!(waited, Err(TransportError::Timeout { .. })), "{waited:?}");
        // 250 ms at 110 ms or more a look: at most 4 looks (the first counts nothing).
        assert!(polls <= 4, "{polls} looks before the timeout");
    }

    /// After `stalls` waits whose yielding stalled, a wait with an answer on its third poll:
    /// found while yielding (which lasts to the deadline if need be), or a timeout if it
    /// blocks at once (nothing notifies, so its one block lasts to the deadline and only 2
    /// polls happen).
    fn after_stalled_yielding(
        tag: &str,
        stalls: u32,
        backoff: Duration,
    ) -> Result<u32, TransportError> {
        let long = Duration::from_secs(60);
        let policy = WaitPolicy { yields: 1, yield_for: long, slice: long, backoff, spins: 0 };
        let ports = world_waiting_with(tag, policy);
        for _ in 0..stalls {
            let mut polls = 0u32;
            // The core held by another process for a time slice: the first poll takes 2 ms.
            let stalled = ports.waiter().wait(&"a stalled answer", Duration::from_secs(5), || {
                polls += 1;
                if polls == 1 {
                    std::thread::sleep(STALLED_YIELDING * 2);
                }
                Ok((polls == 2).then_some(()))
            });
            stalled.expect("found after one yield");
        }
        let mut polls = 0u32;
        ports.waiter().wait(&"the next answer", Duration::from_millis(200), || {
            polls += 1;
            Ok((polls == 3).then_some(polls))
        })
    }

    #[test]
    fn after_stalled_yielding_a_waiter_blocks_at_once_for_its_backoff() {
        let long = Duration::from_secs(60);
        let waited = after_stalled_yielding("backoff", STALLS_TO_BACK_OFF, long);
        assert!(
            matches!(waited, Err(TransportError::Timeout { .. })),
            "the wait after a stall yielded instead of blocking: {waited:?}"
        );
        let yielded = after_stalled_yielding("no-backoff", STALLS_TO_BACK_OFF, Duration::ZERO);
        assert_eq!(yielded.expect("no backoff: found while yielding"), 3);
        // Fewer stalls may be the host's doing: the waiter goes on yielding.
        let yielded = after_stalled_yielding("too-few", STALLS_TO_BACK_OFF - 1, long);
        assert_eq!(yielded.expect("too few stalls: found while yielding"), 3);
    }

    /// How many polls it takes until [`Overdue::check`] says overdue, polling every 1 ms.
    fn polls_until_overdue(mut overdue: Overdue) -> u32 {
        polls_until_overdue_in(&mut overdue).0
    }

    /// [`polls_until_overdue`], going on with `overdue`; also when the poll that said
    /// overdue began, which is no later than the clock [`Overdue::check`] read in it.
    fn polls_until_overdue_in(overdue: &mut Overdue) -> (u32, Instant) {
        for polls in 1..=1000 {
            let began = Instant::now();
            if overdue.check() {
                return (polls, began);
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        panic!("not overdue after 1000 polls of 1 ms")
    }

    /// [`Overdue`] lets a waiter's counted polls pass, which a backing-off waiter does not
    /// make: it then times from the first poll. Once the backoff has run out, the next wait
    /// clears it, and the counted polls are made (and let pass) again.
    #[test]
    fn overdue_lets_pass_the_polls_the_waiter_counts() {
        let (long, backoff, yields) = (Duration::from_secs(60), Duration::from_millis(50), 20);
        let policy = WaitPolicy { yields, yield_for: long, slice: long, backoff, spins: 0 };
        let ports = world_waiting_with("overdue", policy);
        let waiter = ports.waiter();
        // Overdue (`after` zero) at the first poll that reads the clock, or the one after.
        let counted = |polls: u32| polls > yields;
        let polls = polls_until_overdue(waiter.overdue_after(Duration::ZERO, Duration::ZERO));
        assert!(counted(polls), "overdue after {polls} polls: the counted ones were not let pass");
        for _ in 0..STALLS_TO_BACK_OFF {
            let mut polls = 0u32;
            let stalled = waiter.wait(&"a stalled answer", Duration::from_secs(5), || {
                polls += 1;
                if polls == 1 {
                    std::thread::sleep(STALLED_YIELDING * 2);
                }
                Ok((polls == 2).then_some(()))
            });
            stalled.expect("found after one yield");
        }
        let polls = polls_until_overdue(waiter.overdue_after(Duration::ZERO, Duration::ZERO));
        assert!(polls <= 2, "backing off, overdue only after {polls} polls");
        std::thread::sleep(backoff * 2);
        waiter.wait(&"an answer", Duration::from_secs(5), || Ok(Some(()))).expect("found");
        let polls = polls_until_overdue(waiter.overdue_after(Duration::ZERO, Duration::ZERO));
        assert!(counted(polls), "the backoff ran out, yet overdue after {polls} polls");
        // Once overdue, it says so again only `every` later. Timed, not counted in polls: on
        // a loaded machine a sleep of 1 ms lasts longer, so 50 ms may pass in fewer polls.
        let mut overdue = waiter.overdue_after(Duration::ZERO, backoff);
        let (_, first_began) = polls_until_overdue_in(&mut overdue);
        let (polls, _) = polls_until_overdue_in(&mut overdue);
        let apart = first_began.elapsed();
        assert!(apart >= backoff, "overdue again {apart:?} ({polls} polls) later, not {backoff:?}");
    }
}
