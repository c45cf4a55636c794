//! Tick semantics of the behavior-tree engine (SPEC 1.2), driven by scripted leaves.
//!
//! Covers reactive (`AND`, `OR`) against memory (`AND*`, `OR*`) composites, halting of
//! preempted and no-longer-reached RUNNING children (halt counts, progress reset), the
//! parallel node's thresholds and bookkeeping, and every decorator. The SPEC requires our
//! nodes to agree with BehaviorTree.CPP, so the `bt_cpp_*` tests replay scenarios of its test
//! suite (`tests/gtest_sequence.cpp`, `gtest_fallback.cpp`, `gtest_parallel.cpp`,
//! `gtest_decorator.cpp`, `gtest_reactive.cpp`), each naming the test it models. Kinds map
//! as `AND` = ReactiveSequence, `OR` = ReactiveFallback, `AND*` = Sequence, `OR*` =
//! Fallback, `PAR n m=M` = Parallel (success_count M, failure_count n-M+1), `NOT` =
//! Inverter, `REPEAT` = Repeat, `RETRY` = RetryUntilSuccessful. BT.CPP's timed asynchronous
//! actions become actions that take a fixed number of ticks; where our SPEC deliberately
//! differs, the test says so.
//!
//! Each tick is checked as (root status, exact leaf calls): `c=S` a condition check, `a=R`
//! an action tick and its result, `halt a` a halt.

mod common;

use common::{Bt, F, R, S};

// ---------------------------------------------------------------------------------------
// Reactive against memory composites

#[test]
fn reactive_sequence_rechecks_condition_and_halts_running_action() {
    let mut h = Bt::new("AND 2\n- C-c 0\n- A-a 0\n");
    h.set("c", true).takes("a", 10, S);
    h.expect(R, &["c=S", "a=R"]);
    h.expect(R, &["c=S", "a=R"]);
    h.set("c", false);
    h.expect(F, &["c=F", "halt a"]);
    assert_eq!(h.halted(), ["A-a"]);
    assert_eq!(h.get("a").progress_at_halt, [2], "halted with the progress it had reached");
    // Not RUNNING any more: no second halt.
    h.expect(F, &["c=F"]);
    assert_eq!(h.halts("a"), 1);
    h.set("c", true);
    h.expect(R, &["c=S", "a=R"]);
    assert_eq!(h.get("a").progress_seen, [0, 1, 0], "the halted action restarts from 0");
    assert_eq!(h.starts("a"), 2);
}

#[test]
fn memory_sequence_does_not_recheck_condition() {
    let mut h = Bt::new("AND* 2\n- C-c 0\n- A-a 0\n");
    h.set("c", true).takes("a", 4, S);
    h.expect(R, &["c=S", "a=R"]);
    h.set("c", false);
    h.expect(R, &["a=R"]);
    h.expect(R, &["a=R"]);
    h.expect(S, &["a=S"]);
    assert_eq!((h.checks("c"), h.halts("a")), (1, 0));
    // Memory cleared on SUCCESS: the next tick starts at the condition again.
    h.expect(F, &["c=F"]);
}

#[test]
fn reactive_and_memory_sequences_give_different_tick_counts() {
    // The same script for both: the condition holds on ticks 1-2 and fails from tick 3,
    // the action needs 5 ticks.
    let run = |text: &str| {
        let mut h = Bt::new(text);
        h.takes("a", 5, S);
        let statuses: Vec<_> = (1..=6)
            .map(|tick| {
                h.set("c", tick <= 2);
                h.tick()
            })
            .collect();
        (statuses, h.checks("c"), h.ticks("a"), h.halts("a"))
    };
    let reactive = run("AND 2\n- C-c 0\n- A-a 0\n");
    let memory = run("AND* 2\n- C-c 0\n- A-a 0\n");
    assert_eq!(reactive, (vec![R, R, F, F, F, F], 6, 2, 1));
    assert_eq!(memory, (vec![R, R, R, R, S, F], 2, 5, 0));
}

#[test]
fn reactive_fallback_rechecks_condition_and_halts_running_action() {
    let mut h = Bt::new("OR 2\n- C-c 0\n- A-a 0\n");
    h.set("c", false).takes("a", 10, S);
    h.expect(R, &["c=F", "a=R"]);
    h.set("c", true);
    h.expect(S, &["c=S", "halt a"]);
    h.set("c", false);
    h.expect(R, &["c=F", "a=R"]);
    assert_eq!(h.get("a").progress_seen, [0, 0]);
    assert_eq!(h.halts("a"), 1);
}

#[test]
fn memory_fallback_does_not_recheck_condition() {
    let mut h = Bt::new("OR* 2\n- C-c 0\n- A-a 0\n");
    h.set("c", false).takes("a", 3, S);
    h.expect(R, &["c=F", "a=R"]);
    h.set("c", true);
    h.expect(R, &["a=R"]);
    h.expect(S, &["a=S"]);
    // Memory cleared on SUCCESS.
    h.expect(S, &["c=S"]);
    assert_eq!(h.halts("a"), 0);
}

#[test]
fn memory_sequence_clears_memory_on_failure_and_success() {
    // SPEC 1.2: memory is cleared when the node returns SUCCESS *or* FAILURE, as in
    // BT.CPP's Sequence (its SequenceWithMemory keeps it on FAILURE; ours does not).
    let mut h = Bt::new("AND* 3\n- A-a 0\n- A-b 0\n- A-c 0\n");
    h.always("a", S).returns("b", &[R, F, S, R]).always("c", S);
    h.expect(R, &["a=S", "b=R"]);
    h.expect(F, &["b=F"]);
    h.expect(S, &["a=S", "b=S", "c=S"]);
    h.expect(R, &["a=S", "b=R"]);
}

#[test]
fn memory_fallback_clears_memory_on_success_and_failure() {
    let mut h = Bt::new("OR* 3\n- A-a 0\n- A-b 0\n- A-c 0\n");
    h.always("a", F).returns("b", &[R, S, R, F, F]).returns("c", &[S, F]);
    h.expect(R, &["a=F", "b=R"]);
    h.expect(S, &["b=S"]);
    h.expect(R, &["a=F", "b=R"]);
    h.expect(S, &["b=F", "c=S"]);
    h.expect(F, &["a=F", "b=F", "c=F"]);
}

// ---------------------------------------------------------------------------------------
// Halting

#[test]
fn running_child_no_longer_reached_is_halted_and_restarts_from_zero() {
    // `b` runs while `a` fails; once `a` runs instead, `b` is no longer reached.
    let mut h = Bt::new("OR 2\n- A-a 0\n- A-b 0\n");
    h.returns("a", &[F, F, R, F]).takes("b", 10, S);
    h.expect(R, &["a=F", "b=R"]);
    h.expect(R, &["a=F", "b=R"]);
    h.expect(R, &["a=R", "halt b"]);
    assert_eq!(h.halted(), ["A-b"]);
    h.expect(R, &["a=F", "b=R"]);
    assert_eq!(h.get("b").progress_seen, [0, 1, 0]);
    assert_eq!(h.get("b").progress_at_halt, [2]);
    assert_eq!((h.halts("b"), h.starts("b")), (1, 2));
}

#[test]
fn halting_a_subtree_halts_its_running_descendants_and_resets_its_memory() {
    let mut h = Bt::new("AND 2\n- C-c 0\n- OR* 2\n-- A-a 0\n-- A-b 0\n");
    h.set("c", true).always("a", F).always("b", R);
    h.expect(R, &["c=S", "a=F", "b=R"]);
    h.expect(R, &["c=S", "b=R"]);
    h.set("c", false);
    h.expect(F, &["c=F", "halt b"]);
    assert_eq!(h.halted(), ["A-b", "OR*"], "descendants first, then the node");
    h.set("c", true);
    h.expect(R, &["c=S", "a=F", "b=R"]);
}

#[test]
fn an_action_that_finished_is_never_halted() {
    let mut h = Bt::new("OR 2\n- A-a 0\n- A-b 0\n");
    h.returns("a", &[R, F]).returns("b", &[S]);
    h.expect(R, &["a=R"]);
    h.expect(S, &["a=F", "b=S"]);
    h.halt();
    assert!(h.ctx.log.is_empty(), "nothing is RUNNING: {:?}", h.ctx.log);
    assert_eq!((h.halts("a"), h.halts("b")), (0, 0));
}

#[test]
fn tree_halt_halts_every_running_node_once() {
    let mut h = Bt::new("PAR 2 m=2\n- A-a 0\n- A-b 0\n");
    h.always("a", R).always("b", R);
    h.expect(R, &["a=R", "b=R"]);
    h.halt();
    assert_eq!(h.ctx.log, ["halt a", "halt b"]);
    assert_eq!(h.halted(), ["A-a", "A-b", "PAR m=2"]);
    h.halt();
    assert!(h.ctx.log.is_empty());
    h.expect(R, &["a=R", "b=R"]);
    assert_eq!(h.get("a").progress_seen, [0, 0]);
}

// ---------------------------------------------------------------------------------------
// Parallel

#[test]
fn parallel_succeeds_once_m_children_succeeded_and_halts_the_rest() {
    let mut h = Bt::new("PAR 3 m=2\n- A-a 0\n- A-b 0\n- A-c 0\n");
    h.always("a", S).always("b", R).takes("c", 2, S);
    h.expect(R, &["a=S", "b=R", "c=R"]);
    // `a` finished on tick 1 and is not ticked again; `c` makes two: `b` is halted.
    h.expect(S, &["b=R", "c=S", "halt b"]);
    // Reset after returning: every child is ticked again, `b` from progress 0.
    h.expect(R, &["a=S", "b=R", "c=R"]);
    assert_eq!(h.get("b").progress_seen, [0, 1, 0]);
}

#[test]
fn parallel_returns_as_soon_as_the_threshold_is_met() {
    let mut h = Bt::new("PAR 3 m=1\n- A-a 0\n- A-b 0\n- A-c 0\n");
    h.always("a", S);
    h.expect(S, &["a=S"]);
    // A later child still RUNNING from an earlier tick is halted.
    let mut h = Bt::new("PAR 2 m=1\n- A-a 0\n- A-b 0\n");
    h.returns("a", &[R, S]).always("b", R);
    h.expect(R, &["a=R", "b=R"]);
    h.expect(S, &["a=S", "halt b"]);
}

#[test]
fn parallel_fails_once_success_is_impossible() {
    // n = 4, M = 3: FAILURE at n - M + 1 = 2 failures.
    let mut h = Bt::new("PAR 4 m=3\n- A-a 0\n- A-b 0\n- A-c 0\n- A-d 0\n");
    h.returns("a", &[F]).returns("b", &[R, F]).always("c", R).always("d", R);
    h.expect(R, &["a=F", "b=R", "c=R", "d=R"]);
    h.expect(F, &["b=F", "halt c", "halt d"]);
}

#[test]
fn parallel_without_m_needs_every_child() {
    // No `m`: M = n, so the first failure decides.
    let mut h = Bt::new("PAR 3\n- A-a 0\n- A-b 0\n- A-c 0\n");
    h.always("a", S).returns("b", &[F]);
    h.expect(F, &["a=S", "b=F"]);
}

#[test]
fn parallel_does_not_tick_finished_children_until_it_resets() {
    let mut h = Bt::new("PAR 3 m=3\n- A-a 0\n- A-b 0\n- A-c 0\n");
    h.always("a", S).takes("b", 3, S).takes("c", 2, S);
    h.expect(R, &["a=S", "b=R", "c=R"]);
    h.expect(R, &["b=R", "c=S"]);
    h.expect(S, &["b=S"]);
    h.expect(R, &["a=S", "b=R", "c=R"]);
}

#[test]
fn parallel_halted_from_outside_forgets_its_results() {
    let mut h = Bt::new("AND 2\n- C-c 0\n- PAR 2 m=2\n-- A-a 0\n-- A-b 0\n");
    h.set("c", true).always("a", S).always("b", R);
    h.expect(R, &["c=S", "a=S", "b=R"]);
    h.expect(R, &["c=S", "b=R"]);
    h.set("c", false);
    h.expect(F, &["c=F", "halt b"]);
    assert_eq!(h.halted(), ["A-b", "PAR m=2"]);
    h.set("c", true);
    // `a`'s SUCCESS from tick 1 was forgotten.
    h.expect(R, &["c=S", "a=S", "b=R"]);
}

// ---------------------------------------------------------------------------------------
// Decorators

#[test]
fn inverter_swaps_success_and_failure_and_passes_running() {
    let mut h = Bt::new("NOT 1\n- A-a 0\n");
    h.returns("a", &[S, F, R]);
    h.expect(F, &["a=S"]);
    h.expect(S, &["a=F"]);
    h.expect(R, &["a=R"]);
}

#[test]
fn force_success_turns_failure_into_success_and_passes_running() {
    let mut h = Bt::new("FORCE_SUCCESS 1\n- A-a 0\n");
    h.returns("a", &[S, F, R]);
    h.expect(S, &["a=S"]);
    h.expect(S, &["a=F"]);
    h.expect(R, &["a=R"]);
}

#[test]
fn force_failure_turns_success_into_failure_and_passes_running() {
    let mut h = Bt::new("FORCE_FAILURE 1\n- A-a 0\n");
    h.returns("a", &[S, F, R]);
    h.expect(F, &["a=S"]);
    h.expect(F, &["a=F"]);
    h.expect(R, &["a=R"]);
}

#[test]
fn repeat_needs_n_successes_within_the_tick() {
    let mut h = Bt::new("REPEAT 1 n=3\n- A-a 0\n");
    h.always("a", S);
    h.expect(S, &["a=S", "a=S", "a=S"]);
    h.expect(S, &["a=S", "a=S", "a=S"]);
}

#[test]
fn repeat_fails_at_the_first_failure_and_starts_counting_afresh() {
    let mut h = Bt::new("REPEAT 1 n=3\n- A-a 0\n");
    h.returns("a", &[S, F, S, S, S]);
    h.expect(F, &["a=S", "a=F"]);
    h.expect(S, &["a=S", "a=S", "a=S"]);
}

#[test]
fn repeat_count_survives_a_running_child() {
    let mut h = Bt::new("REPEAT 1 n=3\n- A-a 0\n");
    h.returns("a", &[S, R, S, S, S, S, S]);
    h.expect(R, &["a=S", "a=R"]);
    // One success counted on tick 1, two more now.
    h.expect(S, &["a=S", "a=S"]);
    h.expect(S, &["a=S", "a=S", "a=S"]);
}

#[test]
fn retry_until_the_child_succeeds() {
    let mut h = Bt::new("RETRY 1 n=3\n- A-a 0\n");
    h.returns("a", &[F, F, S]);
    h.expect(S, &["a=F", "a=F", "a=S"]);
}

#[test]
fn retry_gives_up_after_n_failures_and_starts_counting_afresh() {
    let mut h = Bt::new("RETRY 1 n=3\n- A-a 0\n");
    h.always("a", F);
    h.expect(F, &["a=F", "a=F", "a=F"]);
    h.expect(F, &["a=F", "a=F", "a=F"]);
}

#[test]
fn retry_count_survives_a_running_child() {
    let mut h = Bt::new("RETRY 1 n=3\n- A-a 0\n");
    h.returns("a", &[F, R, F, F]);
    h.expect(R, &["a=F", "a=R"]);
    h.expect(F, &["a=F", "a=F"]);
}

#[test]
fn halting_a_loop_resets_its_count() {
    let mut h = Bt::new("AND 2\n- C-c 0\n- REPEAT 1 n=3\n-- A-a 0\n");
    h.set("c", true).returns("a", &[S, R, S, S, S]);
    h.expect(R, &["c=S", "a=S", "a=R"]);
    h.set("c", false);
    h.expect(F, &["c=F", "halt a"]);
    assert_eq!(h.halted(), ["A-a", "REPEAT n=3"]);
    h.set("c", true);
    // Three successes needed again, not two.
    h.expect(S, &["c=S", "a=S", "a=S", "a=S"]);
}

#[test]
fn every_decorator_passes_a_halt_to_its_running_child() {
    for (decorator, label) in [
        ("NOT 1", "NOT"),
        ("FORCE_SUCCESS 1", "FORCE_SUCCESS"),
        ("FORCE_FAILURE 1", "FORCE_FAILURE"),
        ("REPEAT 1 n=2", "REPEAT n=2"),
        ("RETRY 1 n=2", "RETRY n=2"),
    ] {
        let mut h = Bt::new(&format!("AND 2\n- C-c 0\n- {decorator}\n-- A-a 0\n"));
        h.set("c", true).always("a", R);
        h.expect(R, &["c=S", "a=R"]);
        h.set("c", false);
        h.expect(F, &["c=F", "halt a"]);
        assert_eq!(h.halted(), ["A-a", label], "{decorator}");
    }
}

// ---------------------------------------------------------------------------------------
// Scenarios of BehaviorTree.CPP's test suite. BT.CPP asserts node statuses (IDLE after a
// reset or halt); we assert the equivalent: which leaves are ticked or halted.

/// gtest_sequence.cpp, SimpleSequenceTest.ConditionTrue (BT.CPP Sequence = `AND*`).
#[test]
fn bt_cpp_simple_sequence_condition_true() {
    let mut h = Bt::new("AND* 2\n- C-condition 0\n- A-action 0\n");
    h.set("condition", true).takes("action", 2, S);
    h.expect(R, &["condition=S", "action=R"]);
}

/// gtest_sequence.cpp, SimpleSequenceTest.ConditionTurnToFalse.
#[test]
fn bt_cpp_simple_sequence_condition_turn_to_false() {
    let mut h = Bt::new("AND* 2\n- C-condition 0\n- A-action 0\n");
    h.set("condition", false);
    h.expect(F, &["condition=F"]);
    h.expect(F, &["condition=F"]);
    assert_eq!(h.ticks("action"), 0);
}

const COMPLEX_SEQUENCE: &str = "
AND 2          # BT.CPP ReactiveSequence
- AND* 2       # Sequence
-- C-condition1 0
-- C-condition2 0
- A-action1 0
";

/// gtest_sequence.cpp, ComplexSequenceTest.ComplexSequenceConditionsTrue.
#[test]
fn bt_cpp_complex_sequence_conditions_true() {
    let mut h = Bt::new(COMPLEX_SEQUENCE);
    h.set("condition1", true).set("condition2", true).takes("action1", 2, S);
    h.expect(R, &["condition1=S", "condition2=S", "action1=R"]);
    assert_eq!(h.returned("AND*"), [S], "the inner sequence finished and reset");
}

/// gtest_sequence.cpp, ComplexSequenceTest.ComplexSequenceConditions1ToFalse.
#[test]
fn bt_cpp_complex_sequence_conditions1_to_false() {
    let mut h = Bt::new(COMPLEX_SEQUENCE);
    h.set("condition1", true).set("condition2", true).takes("action1", 2, S);
    h.expect(R, &["condition1=S", "condition2=S", "action1=R"]);
    h.set("condition1", false);
    h.expect(F, &["condition1=F", "halt action1"]);
}

/// gtest_sequence.cpp, ComplexSequenceTest.ComplexSequenceConditions2ToFalse.
#[test]
fn bt_cpp_complex_sequence_conditions2_to_false() {
    let mut h = Bt::new(COMPLEX_SEQUENCE);
    h.set("condition1", true).set("condition2", true).takes("action1", 2, S);
    h.expect(R, &["condition1=S", "condition2=S", "action1=R"]);
    h.set("condition2", false);
    h.expect(F, &["condition1=S", "condition2=F", "halt action1"]);
}

/// gtest_sequence.cpp, SequenceTripleActionTest.TripleAction: the condition is checked
/// once and each action started once. Its 300 ms actions take 3 ticks here.
#[test]
fn bt_cpp_sequence_triple_action() {
    let mut h = Bt::new("AND* 4\n- C-condition 0\n- A-action1 0\n- A-action2 0\n- A-action3 0\n");
    h.set("condition", true).takes("action1", 3, S).always("action2", S).takes("action3", 3, S);
    h.expect(R, &["condition=S", "action1=R"]);
    assert_eq!(h.run(10), (S, 4));
    assert_eq!(h.checks("condition"), 1);
    assert_eq!([h.starts("action1"), h.ticks("action2"), h.starts("action3")], [1, 1, 1]);
    h.halt();
    assert!(h.ctx.log.is_empty(), "every action is idle");
}

/// gtest_sequence.cpp, ComplexSequence2ActionsTest.ConditionsTrue.
#[test]
fn bt_cpp_complex_sequence_2_actions_conditions_true() {
    let mut h = Bt::new(
        "AND* 2\n- AND* 2\n-- C-condition1 0\n-- A-action1 0\n\
         - AND* 2\n-- C-condition2 0\n-- A-action2 0\n",
    );
    h.set("condition1", true).set("condition2", true);
    h.takes("action1", 3, S).takes("action2", 3, S);
    h.expect(R, &["condition1=S", "action1=R"]);
    h.expect(R, &["action1=R"]);
    h.expect(R, &["action1=S", "condition2=S", "action2=R"]);
}

/// gtest_sequence.cpp, SimpleSequenceWithMemoryTest.ConditionTurnToFalse. BT.CPP's
/// SequenceWithMemory and our `AND*` agree while the sequence is RUNNING.
#[test]
fn bt_cpp_sequence_with_memory_condition_turn_to_false() {
    let mut h = Bt::new("AND* 2\n- C-condition 0\n- A-action 0\n");
    h.set("condition", true).always("action", R);
    h.expect(R, &["condition=S", "action=R"]);
    h.set("condition", false);
    h.expect(R, &["action=R"]);
}

/// gtest_sequence.cpp, ComplexSequenceWithMemoryTest.Conditions1ToFalse.
#[test]
fn bt_cpp_complex_sequence_with_memory_conditions1_to_false() {
    let mut h = Bt::new(
        "AND* 2\n- AND* 2\n-- C-condition1 0\n-- C-condition2 0\n\
         - AND* 2\n-- A-action1 0\n-- A-action2 0\n",
    );
    h.set("condition1", true).set("condition2", true).always("action1", R);
    h.expect(R, &["condition1=S", "condition2=S", "action1=R"]);
    h.set("condition1", false);
    h.expect(R, &["action1=R"]);
    assert_eq!(h.ticks("action2"), 0);
}

/// gtest_sequence.cpp, SequenceWithMemoryTest.Issue_636: a condition fails on 4 ticks,
/// then succeeds. DELIBERATE DIFFERENCE: BT.CPP's SequenceWithMemory keeps its place on
/// FAILURE, so TestA runs once; SPEC 1.2 clears `AND*`'s memory on FAILURE (as BT.CPP's
/// plain Sequence does), so TestA runs on each of the 5 ticks. (The BT.CPP condition is a
/// counter reset by a script before TestA; here it is set per tick.)
#[test]
fn bt_cpp_sequence_with_memory_issue_636() {
    let mut h = Bt::new("AND* 4\n- A-testA 0\n- C-enough 0\n- A-testB 0\n- A-testC 0\n");
    h.always("testA", S).always("testB", S).always("testC", S);
    for _ in 0..4 {
        h.set("enough", false);
        h.expect(F, &["testA=S", "enough=F"]);
    }
    h.set("enough", true);
    h.expect(S, &["testA=S", "enough=S", "testB=S", "testC=S"]);
    assert_eq!([h.ticks("testA"), h.ticks("testB"), h.ticks("testC")], [5, 1, 1]);
}

/// gtest_fallback.cpp, SimpleFallbackTest.ConditionTrue (BT.CPP Fallback = `OR*`).
#[test]
fn bt_cpp_simple_fallback_condition_true() {
    let mut h = Bt::new("OR* 2\n- C-condition 0\n- A-action 0\n");
    h.set("condition", true);
    h.expect(S, &["condition=S"]);
}

/// gtest_fallback.cpp, SimpleFallbackTest.ConditionChangeWhileRunning.
#[test]
fn bt_cpp_simple_fallback_condition_change_while_running() {
    let mut h = Bt::new("OR* 2\n- C-condition 0\n- A-action 0\n");
    h.set("condition", false).always("action", R);
    h.expect(R, &["condition=F", "action=R"]);
    h.set("condition", true);
    h.expect(R, &["action=R"]);
}

const REACTIVE_FALLBACK: &str = "OR 3\n- C-condition1 0\n- C-condition2 0\n- A-action1 0\n";

/// gtest_fallback.cpp, ReactiveFallbackTest.Condition1ToTrue.
#[test]
fn bt_cpp_reactive_fallback_condition1_to_true() {
    let mut h = Bt::new(REACTIVE_FALLBACK);
    h.set("condition1", false).set("condition2", false).takes("action1", 2, S);
    h.expect(R, &["condition1=F", "condition2=F", "action1=R"]);
    h.set("condition1", true);
    h.expect(S, &["condition1=S", "halt action1"]);
}

/// gtest_fallback.cpp, ReactiveFallbackTest.Condition2ToTrue.
#[test]
fn bt_cpp_reactive_fallback_condition2_to_true() {
    let mut h = Bt::new(REACTIVE_FALLBACK);
    h.set("condition1", false).set("condition2", false).takes("action1", 2, S);
    h.expect(R, &["condition1=F", "condition2=F", "action1=R"]);
    h.set("condition2", true);
    h.expect(S, &["condition1=F", "condition2=S", "halt action1"]);
}

const COMPLEX_FALLBACK: &str = "
OR* 2
- OR* 2
-- C-condition1 0
-- C-condition2 0
- OR* 2
-- A-action1 0
-- A-action2 0
";

/// gtest_fallback.cpp, ComplexFallbackWithMemoryTest.ConditionsTrue and Condition1False.
#[test]
fn bt_cpp_complex_fallback_with_memory_conditions_true_and_condition1_false() {
    let mut h = Bt::new(COMPLEX_FALLBACK);
    h.set("condition1", true).set("condition2", true);
    h.expect(S, &["condition1=S"]);
    h.set("condition1", false);
    h.expect(S, &["condition1=F", "condition2=S"]);
}

/// gtest_fallback.cpp, ComplexFallbackWithMemoryTest.ConditionsFalse, Conditions1ToTrue
/// and Conditions2ToTrue: once the actions run, the conditions are not checked again.
#[test]
fn bt_cpp_complex_fallback_with_memory_conditions_false_then_to_true() {
    for turned in ["condition1", "condition2"] {
        let mut h = Bt::new(COMPLEX_FALLBACK);
        h.set("condition1", false).set("condition2", false).always("action1", R);
        h.expect(R, &["condition1=F", "condition2=F", "action1=R"]);
        h.set(turned, true);
        h.expect(R, &["action1=R"]);
    }
}

/// gtest_fallback.cpp, ComplexFallbackWithMemoryTest.Action1Failed.
#[test]
fn bt_cpp_complex_fallback_with_memory_action1_failed() {
    let mut h = Bt::new(COMPLEX_FALLBACK);
    h.set("condition1", false).set("condition2", false);
    h.takes("action1", 3, F).takes("action2", 3, S);
    h.expect(R, &["condition1=F", "condition2=F", "action1=R"]);
    h.expect(R, &["action1=R"]);
    h.expect(R, &["action1=F", "action2=R"]);
    assert_eq!(h.checks("condition1"), 1);
}

const SIMPLE_PARALLEL: &str = "
PAR 4 m={m}
- C-condition1 0
- A-action1 0
- C-condition2 0
- A-action2 0
";

fn simple_parallel(m: u32) -> Bt {
    let mut h = Bt::new(&SIMPLE_PARALLEL.replace("{m}", &m.to_string()));
    h.set("condition1", true).set("condition2", true);
    h
}

/// gtest_parallel.cpp, SimpleParallelTest.ConditionsTrue (success threshold 4; also
/// Threshold_neg1, whose -1 means "all").
#[test]
fn bt_cpp_parallel_conditions_true() {
    let mut h = simple_parallel(4);
    h.takes("action1", 2, S).takes("action2", 3, S);
    h.expect(R, &["condition1=S", "action1=R", "condition2=S", "action2=R"]);
    h.expect(R, &["action1=S", "action2=R"]);
    h.expect(S, &["action2=S"]);
}

/// gtest_parallel.cpp, SimpleParallelTest.Threshold_3 (and Threshold_neg2, -2 = 3 of 4).
#[test]
fn bt_cpp_parallel_threshold_3() {
    let mut h = simple_parallel(3);
    h.takes("action1", 2, S).takes("action2", 6, S);
    h.expect(R, &["condition1=S", "action1=R", "condition2=S", "action2=R"]);
    h.expect(S, &["action1=S", "halt action2"]);
}

/// gtest_parallel.cpp, SimpleParallelTest.Threshold_2: two conditions suffice within the
/// first tick; action1 is halted and action2 never ticked.
#[test]
fn bt_cpp_parallel_threshold_2() {
    let mut h = simple_parallel(2);
    h.takes("action1", 2, S).takes("action2", 2, S);
    h.expect(S, &["condition1=S", "action1=R", "condition2=S", "halt action1"]);
    assert_eq!(h.ticks("action2"), 0);
}

/// gtest_parallel.cpp, SimpleParallelTest.Threshold_thresholdFneg1: success 1, failure
/// "all" = our failure count n - M + 1 = 4.
#[test]
fn bt_cpp_parallel_threshold_f_neg1() {
    let mut h = simple_parallel(1);
    h.set("condition1", false).set("condition2", false);
    h.takes("action1", 2, F).takes("action2", 3, F);
    h.expect(R, &["condition1=F", "action1=R", "condition2=F", "action2=R"]);
    h.expect(R, &["action1=F", "action2=R"]);
    h.expect(F, &["action2=F"]);
}

/// ComplexParallelTest of gtest_parallel.cpp, with `{left}` the left node's M.
const COMPLEX_PARALLEL: &str = "
PAR 2 m=2
- PAR 4 m={left}
-- C-condL1 0
-- A-actL1 0
-- C-condL2 0
-- A-actL2 0
- PAR 2 m=1
-- C-condR 0
-- A-actR 0
";

fn complex_parallel(left: u32) -> Bt {
    let mut h = Bt::new(&COMPLEX_PARALLEL.replace("{left}", &left.to_string()));
    h.set("condL1", true).set("condL2", true).set("condR", true);
    h
}

/// gtest_parallel.cpp, ComplexParallelTest.ConditionsTrue: the right node succeeds on
/// tick 1 and is not ticked again; the left one succeeds on tick 2.
#[test]
fn bt_cpp_complex_parallel_conditions_true() {
    let mut h = complex_parallel(3);
    h.takes("actL1", 2, S).takes("actL2", 3, S).takes("actR", 5, S);
    h.expect(R, &["condL1=S", "actL1=R", "condL2=S", "actL2=R", "condR=S"]);
    h.expect(S, &["actL1=S", "halt actL2"]);
    assert_eq!((h.checks("condR"), h.ticks("actR")), (1, 0));
}

/// gtest_parallel.cpp, ComplexParallelTest.ConditionsLeftFalse: the left node fails as
/// soon as success is impossible (2 of 4 failed with M = 3), which fails the root.
#[test]
fn bt_cpp_complex_parallel_conditions_left_false() {
    let mut h = complex_parallel(3);
    h.set("condL1", false).set("condL2", false).always("actL1", R);
    h.expect(F, &["condL1=F", "actL1=R", "condL2=F", "halt actL1"]);
    assert_eq!((h.ticks("actL2"), h.checks("condR")), (0, 0));
}

/// gtest_parallel.cpp, ComplexParallelTest.ConditionRightFalse_thresholdF_2. Our right
/// node (n = 2, M = 1) has failure count 2 by construction. DELIBERATE DIFFERENCE: BT.CPP's
/// default failure_count is 1, so its ComplexParallelTest.ConditionRightFalse (root fails
/// at once) has no counterpart here.
#[test]
fn bt_cpp_complex_parallel_condition_right_false_threshold_f_2() {
    let mut h = complex_parallel(3);
    h.set("condR", false).takes("actL1", 2, S).takes("actL2", 2, S).takes("actR", 2, S);
    h.expect(R, &["condL1=S", "actL1=R", "condL2=S", "actL2=R", "condR=F", "actR=R"]);
    h.expect(S, &["actL1=S", "halt actL2", "actR=S"]);
}

/// gtest_parallel.cpp, ComplexParallelTest.ConditionRightFalseAction1Done: left needs all
/// 4 and finishes on tick 2, then is not ticked while the right one runs on.
#[test]
fn bt_cpp_complex_parallel_condition_right_false_action1_done() {
    let mut h = complex_parallel(4);
    h.set("condR", false).takes("actL1", 2, S).takes("actL2", 2, S).takes("actR", 3, S);
    h.expect(R, &["condL1=S", "actL1=R", "condL2=S", "actL2=R", "condR=F", "actR=R"]);
    h.expect(R, &["actL1=S", "actL2=S", "actR=R"]);
    h.expect(S, &["actR=S"]);
}

/// gtest_parallel.cpp, Parallel.FailingParallel: success_count 1, failure_count 3 with 3
/// children, exactly our `PAR 3 m=1`.
#[test]
fn bt_cpp_parallel_failing_parallel() {
    let mut h = Bt::new("PAR 3 m=1\n- A-first 0\n- A-second 0\n- A-third 0\n");
    h.takes("first", 2, S).takes("second", 1, F).takes("third", 3, S);
    h.expect(R, &["first=R", "second=F", "third=R"]);
    h.expect(S, &["first=S", "halt third"]);
}

/// gtest_parallel.cpp, Parallel.Issue819_SequenceVsReactiveSequence (success 2, failure
/// 1 = our n - M + 1 with n = M = 2).
#[test]
fn bt_cpp_parallel_issue819_sequence_vs_reactive_sequence() {
    for (kind, checks) in [("AND*", 1), ("AND", 2)] {
        let mut h = Bt::new(&format!(
            "PAR 2 m=2\n- {kind} 2\n-- C-cond1 0\n-- A-sleep1 0\n\
             - {kind} 2\n-- C-cond2 0\n-- A-sleep2 0\n"
        ));
        h.set("cond1", true).set("cond2", true).always("sleep1", R).always("sleep2", R);
        assert_eq!(h.tick(), R);
        assert_eq!(h.tick(), R);
        assert_eq!((h.checks("cond1"), h.checks("cond2")), (checks, checks), "{kind}");
    }
}

/// gtest_decorator.cpp, RetryTest.RetryTestA.
#[test]
fn bt_cpp_retry_test_a() {
    let mut h = Bt::new("RETRY 1 n=3\n- A-action 0\n");
    h.always("action", F);
    assert_eq!(h.tick(), F);
    assert_eq!(h.ticks("action"), 3);
    h.always("action", S);
    assert_eq!(h.tick(), S);
    assert_eq!(h.ticks("action"), 3 + 1);
}

/// gtest_decorator.cpp, RepeatTest.RepeatTestA.
#[test]
fn bt_cpp_repeat_test_a() {
    let mut h = Bt::new("REPEAT 1 n=3\n- A-action 0\n");
    h.always("action", F);
    assert_eq!(h.tick(), F);
    assert_eq!(h.ticks("action"), 1);
    h.always("action", S);
    assert_eq!(h.tick(), S);
    assert_eq!(h.ticks("action"), 1 + 3);
}

/// gtest_decorator.cpp, RepeatTestAsync.RepeatTestAsync: an asynchronous child succeeds
/// 3 times, then fails once. (BT.CPP yields after each asynchronous success; we restart the
/// child within the tick, so the tick count differs but the successes do not.)
#[test]
fn bt_cpp_repeat_test_async() {
    let mut h = Bt::new("REPEAT 1 n=3\n- A-action 0\n");
    h.takes("action", 2, S);
    h.expect(R, &["action=R"]);
    h.expect(R, &["action=S", "action=R"]);
    h.expect(R, &["action=S", "action=R"]);
    h.expect(S, &["action=S"]);
    assert_eq!(h.starts("action"), 3);
    h.takes("action", 2, F);
    assert_eq!(h.run(10), (F, 2));
    assert_eq!(h.starts("action"), 3 + 1);
}

/// gtest_decorator.cpp, Decorator.ForceFailure_ChildSuccess, ForceFailure_ChildFailure,
/// ForceSuccess_ChildFailure, ForceSuccess_ChildSuccess, Inverter_ChildSuccess and
/// Inverter_ChildFailure.
#[test]
fn bt_cpp_decorator_force_and_inverter_children() {
    for (decorator, child, expected) in [
        ("FORCE_FAILURE", S, F),
        ("FORCE_FAILURE", F, F),
        ("FORCE_SUCCESS", F, S),
        ("FORCE_SUCCESS", S, S),
        ("NOT", S, F),
        ("NOT", F, S),
    ] {
        let mut h = Bt::new(&format!("{decorator} 1\n- A-child 0\n"));
        h.always("child", child);
        assert_eq!(h.run(1), (expected, 1), "{decorator} over {child}");
    }
}

/// gtest_decorator.cpp, Decorator.Inverter_InSequence.
#[test]
fn bt_cpp_decorator_inverter_in_sequence() {
    let mut h = Bt::new("AND* 2\n- NOT 1\n-- A-alwaysFailure 0\n- A-alwaysSuccess 0\n");
    h.always("alwaysFailure", F).always("alwaysSuccess", S);
    h.expect(S, &["alwaysFailure=F", "alwaysSuccess=S"]);
}

/// gtest_reactive.cpp, Reactive.RunningChildren: a reactive sequence re-ticks its finished
/// first branch on every tick while the second, with memory, resumes where it was. BT.CPP's
/// AsyncSequence (yields after each child) has no counterpart; here D, E, F each take two
/// ticks, so the run takes 4 ticks instead of 3, and each of them still starts once.
#[test]
fn bt_cpp_reactive_running_children() {
    let mut h = Bt::new(
        "AND 2\n- AND* 3\n-- A-testA 0\n-- A-testB 0\n-- A-testC 0\n\
         - AND* 3\n-- A-testD 0\n-- A-testE 0\n-- A-testF 0\n",
    );
    for name in ["testA", "testB", "testC"] {
        h.always(name, S);
    }
    for name in ["testD", "testE", "testF"] {
        h.takes(name, 2, S);
    }
    let (status, ticks) = h.run(100);
    assert_eq!((status, ticks), (S, 4));
    for name in ["testA", "testB", "testC"] {
        assert_eq!(h.ticks(name), ticks, "{name} ticked on every tick");
    }
    for name in ["testD", "testE", "testF"] {
        assert_eq!(h.starts(name), 1, "{name} started once");
    }
}

/// gtest_reactive.cpp, Reactive.ReactiveSequence_FirstChildFails.
#[test]
fn bt_cpp_reactive_sequence_first_child_fails() {
    let mut h = Bt::new("AND 2\n- A-alwaysFailure 0\n- A-testA 0\n");
    h.always("alwaysFailure", F);
    h.expect(F, &["alwaysFailure=F"]);
}

/// gtest_reactive.cpp, Reactive.ReactiveSequence_HaltOnConditionChange.
#[test]
fn bt_cpp_reactive_sequence_halt_on_condition_change() {
    let mut h = Bt::new("AND 2\n- C-dynamic 0\n- A-tracking 0\n");
    h.set("dynamic", true).always("tracking", R);
    assert_eq!(h.tick(), R);
    assert_eq!(h.tick(), R);
    assert_eq!((h.ticks("tracking"), h.halts("tracking")), (2, 0));
    h.set("dynamic", false);
    assert_eq!(h.tick(), F);
    assert_eq!(h.halts("tracking"), 1);
}

/// gtest_reactive.cpp, Reactive.ReactiveFallback_FirstChildSucceeds.
#[test]
fn bt_cpp_reactive_fallback_first_child_succeeds() {
    let mut h = Bt::new("OR 2\n- A-alwaysSuccess 0\n- A-testA 0\n");
    h.always("alwaysSuccess", S);
    h.expect(S, &["alwaysSuccess=S"]);
}

/// gtest_reactive.cpp, Reactive.ReactiveFallback_AllChildrenFail (three instances of one
/// leaf, as in BT.CPP).
#[test]
fn bt_cpp_reactive_fallback_all_children_fail() {
    let mut h = Bt::new("OR 3\n- A-alwaysFailure 0\n- A-alwaysFailure 0\n- A-alwaysFailure 0\n");
    h.always("alwaysFailure", F);
    h.expect(F, &["alwaysFailure=F", "alwaysFailure=F", "alwaysFailure=F"]);
}

/// gtest_reactive.cpp, Reactive.ReactiveFallback_SecondChildSucceeds.
#[test]
fn bt_cpp_reactive_fallback_second_child_succeeds() {
    let mut h = Bt::new("OR 2\n- A-alwaysFailure 0\n- A-testA 0\n");
    h.always("alwaysFailure", F).always("testA", S);
    h.expect(S, &["alwaysFailure=F", "testA=S"]);
}

/// gtest_reactive.cpp, Reactive.ReactiveSequence_AllChildrenSucceed.
#[test]
fn bt_cpp_reactive_sequence_all_children_succeed() {
    let mut h = Bt::new("AND 3\n- A-testA 0\n- A-testB 0\n- A-testC 0\n");
    h.always("testA", S).always("testB", S).always("testC", S);
    h.expect(S, &["testA=S", "testB=S", "testC=S"]);
}

/// gtest_reactive.cpp, Reactive.ReactiveSequence_ReEvaluatesOnEveryTick.
#[test]
fn bt_cpp_reactive_sequence_re_evaluates_on_every_tick() {
    let mut h = Bt::new("AND 2\n- C-counting 0\n- A-sleep 0\n");
    h.set("counting", true).takes("sleep", 3, S);
    assert_eq!(h.run(10), (S, 3));
    assert_eq!(h.checks("counting"), 3);
}
