//! The learning selector (`LOR`, SPEC 1.3) driven by scripted leaves and a settable RL state.
//!
//! Covers the order children are tried in (Q descending, ties broken by the seeded RNG,
//! uniformly random with probability epsilon), when and how Q-values change (a FAILURE is
//! a step with s' = s taken before the next child; a SUCCESS or RUNNING child's step is
//! completed at the selector's next tick with the state observed then; terminal and
//! truncated episode ends), halting of a RUNNING child that is not chosen again, duplicate
//! children as distinct actions, and `learn: false`. Every expected Q-value is written out
//! as the arithmetic of the update Q(s,a) += alpha * (r + gamma * max_b Q(s',b) - Q(s,a))
//! with r = -1 and the alpha, gamma given in the test.

mod common;

use common::{assert_close, table, Bt, F, R, S};
use flockstep_agents::learning::LearnParams;
use flockstep_agents::FIG5_TREE;

/// alpha 0.5, gamma 0.5: every value below is exact in binary, greedy (epsilon 0).
const P: LearnParams = LearnParams { alpha: 0.5, gamma: 0.5, epsilon: 0.0, learn: true };

fn frozen(epsilon: f64) -> LearnParams {
    LearnParams { alpha: 0.5, gamma: 0.5, epsilon, learn: false }
}

const ABC: &str = "LOR 3\n- A-a 0\n- A-b 0\n- A-c 0\n";
const ABCD: &str = "LOR 4\n- A-a 0\n- A-b 0\n- A-c 0\n- A-d 0\n";

#[test]
fn children_are_tried_by_q_descending_in_the_observed_state() {
    let mut h = Bt::with(ABC, frozen(0.0), 1);
    h.tree.set_tables(vec![table(3, &[(2, &[-3.0, -1.0, -2.0]), (5, &[3.0, 1.0, 2.0])])]).unwrap();
    h.always("a", F).always("b", F).always("c", F);
    h.ctx.state = 2;
    h.expect(F, &["b=F", "c=F", "a=F"]);
    assert_eq!(h.chosen(), [1, 2, 0]);
    h.ctx.state = 5;
    h.expect(F, &["a=F", "c=F", "b=F"]);
    // Like a selector, it stops at the first child that does not fail.
    h.always("c", S);
    h.ctx.state = 2;
    h.expect(S, &["b=F", "c=S"]);
}

/// The orders (children as tried) of `ticks` ticks of four always-failing children.
fn orders(seed: u64, q: [f64; 4], ticks: usize) -> Vec<Vec<u32>> {
    let mut h = Bt::with(ABCD, frozen(0.0), seed);
    h.tree.set_tables(vec![table(4, &[(0, &q)])]).unwrap();
    for name in ["a", "b", "c", "d"] {
        h.always(name, F);
    }
    (0..ticks)
        .map(|_| {
            assert_eq!(h.tick(), F);
            h.chosen()
        })
        .collect()
}

#[test]
fn ties_are_broken_by_the_seeded_rng() {
    let seven = orders(7, [0.0; 4], 40);
    for order in &seven {
        let mut sorted = order.clone();
        sorted.sort();
        assert_eq!(sorted, [0, 1, 2, 3], "each child tried once per tick: {order:?}");
    }
    assert_eq!(seven, orders(7, [0.0; 4], 40), "same seed, same orders");
    assert_ne!(seven, orders(8, [0.0; 4], 40), "another seed, other orders");
    let mut first: Vec<u32> = seven.iter().map(|order| order[0]).collect();
    first.sort();
    first.dedup();
    assert_eq!(first, [0, 1, 2, 3], "every child comes first on some tick");
}

#[test]
fn only_tied_children_are_shuffled() {
    // a and c tie at the top, b and d below.
    let all = orders(3, [0.0, -1.0, 0.0, -1.0], 40);
    for order in &all {
        let (mut top, mut bottom) = (order[..2].to_vec(), order[2..].to_vec());
        top.sort();
        bottom.sort();
        assert_eq!((top, bottom), (vec![0, 2], vec![1, 3]), "{order:?}");
    }
    assert!(all.iter().any(|order| order[0] == 0) && all.iter().any(|order| order[0] == 2));
    assert!(all.iter().any(|order| order[2] == 1) && all.iter().any(|order| order[2] == 3));
}

#[test]
fn epsilon_zero_with_distinct_q_is_deterministic() {
    for seed in 1..=5 {
        let all = orders(seed, [0.1, 0.4, 0.3, 0.2], 20);
        assert!(all.iter().all(|order| order == &[1, 2, 3, 0]), "seed {seed}: {all:?}");
    }
}

/// How often each child was tried first in `ticks` ticks, with distinct Q-values that
/// make child 0 the greedy choice.
fn first_choices(epsilon: f64, ticks: u32) -> [u32; 4] {
    let mut h = Bt::with(ABCD, frozen(epsilon), 42);
    h.tree.set_tables(vec![table(4, &[(0, &[3.0, 2.0, 1.0, 0.0])])]).unwrap();
    for name in ["a", "b", "c", "d"] {
        h.always(name, S);
    }
    let mut counts = [0; 4];
    for _ in 0..ticks {
        assert_eq!(h.tick(), S);
        let chosen = h.chosen();
        assert_eq!(chosen.len(), 1);
        counts[chosen[0] as usize] += 1;
    }
    counts
}

#[test]
fn epsilon_one_gives_uniformly_random_first_choices() {
    let counts = first_choices(1.0, 4000);
    // 1000 expected each, standard deviation ~27: the bounds are over 4 sigma wide.
    for (child, &n) in counts.iter().enumerate() {
        assert!((880..=1120).contains(&n), "child {child} first {n} times of 4000: {counts:?}");
    }
    let chi2: f64 = counts.iter().map(|&n| (n as f64 - 1000.0).powi(2) / 1000.0).sum();
    // 16.27 is the 0.999 quantile of chi-square with 3 degrees of freedom.
    assert!(chi2 < 16.27, "chi-square {chi2} for {counts:?}");
}

#[test]
fn epsilon_is_the_probability_of_a_random_order() {
    // With epsilon 0.2 a random order comes first 20% of the time and puts a non-greedy
    // child first 3/4 of those times: 4000 * 0.2 * 0.75 = 600 expected, sd ~23.
    let counts = first_choices(0.2, 4000);
    let non_greedy: u32 = counts[1..].iter().sum();
    assert!((500..=700).contains(&non_greedy), "{counts:?}");
    assert_eq!(first_choices(0.0, 200), [200, 0, 0, 0]);
}

#[test]
fn a_failing_child_is_updated_with_s_prime_equal_s_before_the_next_child() {
    let mut h = Bt::with(ABC, P, 1);
    h.tree
        .set_tables(vec![table(3, &[(0, &[4.0, 2.0, 0.0]), (9, &[100.0, 100.0, 101.0])])])
        .unwrap();
    h.always("a", F).always("b", F).always("c", S);
    // Ticking `a` moves the world to state 9: the FAILURE steps still use s' = 0, the state
    // the selector observed at the start of its tick.
    h.action("a").moves_state_to = Some(9);
    h.expect(S, &["a=F", "b=F", "c=S"]);
    assert_eq!(h.ctx.observations, 1, "the state is observed once per tick");
    let qa = 4.0 + 0.5 * (-1.0 + 0.5 * 4.0 - 4.0); // max Q(0, .) = Q(0,a) = 4
    let qb = 2.0 + 0.5 * (-1.0 + 0.5 * qa - 2.0); // max Q(0, .) = Q(0,a) updated = 2.5
                                                  // Had a's update waited until after b was tried, b's target would use max = 4: 1.5.
    let row = h.row(0, 0);
    assert_close(row[0], qa);
    assert_close(row[1], qb);
    assert_eq!(row[2], 0.0, "c's step waits for the next tick");
    assert_eq!(h.row(0, 9), [100.0, 100.0, 101.0]);
    // Next tick, in state 9: c's step completes with s' = 9.
    h.expect(S, &["c=S"]);
    assert_eq!(h.ctx.observations, 2);
    assert_close(h.table(0).get(0, 2), 0.0 + 0.5 * (-1.0 + 0.5 * 101.0 - 0.0));
}

#[test]
fn a_running_child_gets_one_update_per_tick_with_the_next_state() {
    let mut h = Bt::with("LOR 2\n- A-a 0\n- A-b 0\n", P, 1);
    let preload = table(2, &[(0, &[0.0, -10.0]), (1, &[4.0, -10.0]), (2, &[6.0, -10.0])]);
    h.tree.set_tables(vec![preload.clone()]).unwrap();
    h.always("a", R).always("b", F);
    h.ctx.state = 0;
    h.expect(R, &["a=R"]);
    assert_eq!(h.table(0), preload, "no update within the tick a ran");
    h.ctx.state = 1;
    h.expect(R, &["a=R"]);
    let q0a = 0.0 + 0.5 * (-1.0 + 0.5 * 4.0 - 0.0);
    assert_close(h.table(0).get(0, 0), q0a);
    assert_eq!(h.row(0, 1), [4.0, -10.0]);
    h.ctx.state = 2;
    h.expect(R, &["a=R"]);
    assert_close(h.table(0).get(0, 0), q0a);
    let q1a = 4.0 + 0.5 * (-1.0 + 0.5 * 6.0 - 4.0);
    assert_close(h.table(0).get(1, 0), q1a);
    assert_eq!(h.row(0, 2), [6.0, -10.0]);
    assert_eq!(h.get("a").progress_seen, [0, 1, 2], "chosen again: not halted");
    assert_eq!(h.halts("a"), 0);
}

#[test]
fn a_running_child_not_chosen_again_is_halted() {
    let mut h = Bt::with("LOR 2\n- A-a 0\n- A-b 0\n", frozen(0.0), 1);
    h.tree.set_tables(vec![table(2, &[(0, &[1.0, 0.0]), (1, &[0.0, 1.0])])]).unwrap();
    h.always("a", R).always("b", R);
    h.ctx.state = 0;
    h.expect(R, &["a=R"]);
    h.ctx.state = 1;
    h.expect(R, &["b=R", "halt a"]);
    assert_eq!(h.halted(), ["A-a"]);
    h.expect(R, &["b=R"]);
    h.ctx.state = 0;
    h.expect(R, &["a=R", "halt b"]);
    assert_eq!(h.get("a").progress_seen, [0, 0], "the halted child restarts");
    assert_eq!(h.get("b").progress_at_halt, [2]);
    assert_eq!((h.halts("a"), h.halts("b")), (1, 1));
}

#[test]
fn a_running_child_that_fails_when_tried_again_is_not_halted() {
    let mut h = Bt::with("LOR 2\n- A-a 0\n- A-b 0\n", frozen(0.0), 1);
    h.tree.set_tables(vec![table(2, &[(0, &[1.0, 0.0])])]).unwrap();
    h.returns("a", &[R, F]).always("b", S);
    h.expect(R, &["a=R"]);
    h.expect(S, &["a=F", "b=S"]);
    assert_eq!(h.halts("a"), 0);
}

#[test]
fn a_selector_halted_by_its_parent_halts_its_child_and_keeps_the_pending_step() {
    let mut h = Bt::with("OR 2\n- C-done 0\n- LOR 2\n-- A-a 0\n-- A-b 0\n", P, 1);
    h.tree.set_tables(vec![table(2, &[(0, &[1.0, 0.0]), (2, &[0.0, -5.0])])]).unwrap();
    h.always("a", R).always("b", F);
    h.ctx.state = 0;
    h.expect(R, &["done=F", "a=R"]);
    h.set("done", true);
    h.ctx.state = 1;
    h.expect(S, &["done=S", "halt a"]);
    assert_eq!(h.halted(), ["A-a", "LOR"]);
    assert_eq!(h.table(0).get(0, 0), 1.0, "the selector did not tick: no update");
    h.set("done", false);
    h.ctx.state = 2;
    h.expect(R, &["done=F", "a=R"]);
    // The step of tick 1 completes at the selector's next tick, in state 2.
    assert_close(h.table(0).get(0, 0), 1.0 + 0.5 * (-1.0 + 0.5 * 0.0 - 1.0));
    assert_eq!(h.get("a").progress_seen, [0, 0]);
}

#[test]
fn when_every_child_fails_each_is_updated_and_nothing_is_pending() {
    let mut h = Bt::with("LOR 2\n- A-a 0\n- A-b 0\n", P, 1);
    h.tree.set_tables(vec![table(2, &[(0, &[1.0, 0.0])])]).unwrap();
    h.always("a", F).always("b", F);
    h.expect(F, &["a=F", "b=F"]);
    let qa = 1.0 + 0.5 * (-1.0 + 0.5 * 1.0 - 1.0);
    let qb = 0.0 + 0.5 * (-1.0 + 0.5 * f64::max(qa, 0.0) - 0.0);
    let after = h.table(0);
    assert_close(after.get(0, 0), qa);
    assert_close(after.get(0, 1), qb);
    h.tree.end_episode_terminal();
    h.tree.end_episode_truncated(0);
    assert_eq!(h.table(0), after);
}

/// A tree whose selector ran `a` (SUCCESS) in state 0, about to end in state 1.
fn one_step_taken() -> Bt {
    let mut h = Bt::with("LOR 2\n- A-a 0\n- A-b 0\n", P, 1);
    h.tree.set_tables(vec![table(2, &[(0, &[2.0, 0.0]), (1, &[8.0, 8.0])])]).unwrap();
    h.always("a", S).always("b", S);
    h.ctx.state = 0;
    h.expect(S, &["a=S"]);
    h.ctx.state = 1;
    h
}

#[test]
fn a_terminal_episode_end_updates_without_bootstrap() {
    let mut h = one_step_taken();
    h.tree.end_episode_terminal();
    let terminal = 2.0 + 0.5 * (-1.0 - 2.0);
    assert_close(h.table(0).get(0, 0), terminal);
    // (A bootstrap from state 1 would have given 2 + 0.5 * (-1 + 0.5 * 8 - 2) = 2.5.)
    assert_eq!(h.row(0, 1), [8.0, 8.0]);
    // The step is consumed: neither another end nor the next tick updates it again.
    h.tree.end_episode_truncated(1);
    assert_close(h.table(0).get(0, 0), terminal);
    assert_eq!(h.tick(), S);
    assert_close(h.table(0).get(0, 0), terminal);
}

#[test]
fn a_truncated_episode_end_bootstraps_from_the_last_state() {
    let mut h = one_step_taken();
    h.tree.end_episode_truncated(1);
    let truncated = 2.0 + 0.5 * (-1.0 + 0.5 * 8.0 - 2.0);
    assert_close(h.table(0).get(0, 0), truncated);
    h.tree.end_episode_terminal();
    assert_close(h.table(0).get(0, 0), truncated);
}

#[test]
fn duplicate_children_are_distinct_actions() {
    let text = "LOR 3\n- A-rotate 0\n- A-elevate 0\n- A-rotate 0\n";
    for (row, chosen) in [([-5.0, -10.0, 0.0], 2), ([0.0, -10.0, -5.0], 0)] {
        let mut h = Bt::with(text, P, 1);
        h.tree.set_tables(vec![table(3, &[(0, &row)])]).unwrap();
        h.always("rotate", S).always("elevate", S);
        h.expect(S, &["rotate=S"]);
        assert_eq!(h.chosen(), [chosen]);
        h.ctx.state = 1;
        assert_eq!(h.tick(), S);
        let mut expected = row;
        expected[chosen as usize] =
            row[chosen as usize] + 0.5 * (-1.0 + 0.5 * 0.0 - row[chosen as usize]);
        let got = h.row(0, 0);
        for child in 0..3 {
            assert_close(got[child], expected[child]);
        }
    }
}

#[test]
fn duplicate_children_run_and_halt_separately() {
    let mut h = Bt::with("LOR 2\n- A-rotate 0\n- A-rotate 0\n", frozen(0.0), 1);
    h.tree.set_tables(vec![table(2, &[(0, &[1.0, 0.0]), (1, &[0.0, 1.0])])]).unwrap();
    h.always("rotate", R);
    h.expect(R, &["rotate=R"]);
    h.expect(R, &["rotate=R"]);
    h.ctx.state = 1;
    h.expect(R, &["rotate=R", "halt rotate"]);
    // The second child has its own progress: it starts at 0 although the first was at 2.
    assert_eq!(h.get("rotate").progress_seen, [0, 1, 0]);
    assert_eq!(h.get("rotate").progress_at_halt, [2]);
}

#[test]
fn learn_false_never_changes_a_table() {
    let text = "OR 2\n- C-done 0\n- LOR 3\n-- A-a 0\n-- A-b 0\n-- A-c 0\n";
    let preload = table(3, &[(0, &[1.0, 2.0, 3.0]), (1, &[-1.0, 0.5, 0.0]), (2, &[0.0; 3])]);
    let run = |learn: bool| {
        let params = LearnParams { alpha: 0.5, gamma: 0.5, epsilon: 0.5, learn };
        let mut h = Bt::with(text, params, 9);
        h.tree.set_tables(vec![preload.clone()]).unwrap();
        h.takes("a", 2, S).always("b", F).returns("c", &[R, S].repeat(200));
        let mut explored = false;
        for tick in 0..200u32 {
            h.ctx.state = tick % 3;
            h.set("done", tick % 7 == 6);
            h.tick();
            explored |= h.chosen().first().is_some_and(|&c| c != 2 && tick % 3 == 0);
            if tick % 50 == 49 {
                h.tree.end_episode_terminal();
            } else if tick % 50 == 24 {
                h.tree.end_episode_truncated(1);
            }
        }
        (h.table(0), explored)
    };
    let (frozen_table, explored) = run(false);
    assert!(explored, "the run explored, so learning would have had much to change");
    assert_eq!(frozen_table, preload);
    assert_ne!(run(true).0, preload, "the same run with learning changes the table");
}

#[test]
fn fig5_terminal_credit_goes_to_the_choice_that_revealed_the_target() {
    let params = LearnParams { alpha: 0.1, gamma: 1.0, epsilon: 0.0, learn: true };
    let mut h = Bt::with(FIG5_TREE, params, 5);
    for name in ["rotate", "elevate", "deElevate", "waypointTranslation", "endEpisode"] {
        h.always(name, S);
    }
    h.ctx.state = 0;
    assert_eq!(h.tick(), S);
    let first = h.chosen()[0] as usize;
    h.ctx.state = 1;
    assert_eq!(h.tick(), S);
    let second = h.chosen()[0] as usize;
    // All Q were 0: the first step's target is -1 + 1.0 * max Q(1, .) = -1.
    assert_close(h.table(0).get(0, first), 0.0 + 0.1 * (-1.0 + 1.0 * 0.0 - 0.0));
    assert_eq!(h.row(0, 1), [0.0; 5]);
    // The target comes into view: the AND branch ends the episode, the LOR is not ticked.
    h.set("seeTarget", true);
    h.ctx.state = 2;
    h.expect(S, &["seeTarget=S", "endEpisode=S"]);
    assert_eq!(h.row(0, 1), [0.0; 5]);
    h.tree.end_episode_terminal();
    let mut expected = [0.0; 5];
    expected[second] = 0.0 + 0.1 * (-1.0 - 0.0);
    assert_eq!(h.row(0, 1), expected);
    let updated = h.row(0, 0).iter().filter(|&&q| q != 0.0).count();
    assert_eq!(updated, 1, "state 0 has only the first step's update");
}

#[test]

fn a_nested_selector_that_fails_lets_the_outer_try_its_next_child() {
    let mut h = Bt::with("LOR 2\n- LOR 2\n-- A-a 0\n-- A-b 0\n- A-c 0\n", frozen(0.0), 1);
    let prefer_first = table(2, &[(0, &[1.0, 0.0])]);
    h.tree.set_tables(vec![prefer_first.clone(), prefer_first]).unwrap();
    h.always("a", F).always("b", F).always("c", S);
    h.expect(S, &["a=F", "b=F", "c=S"]);
    // Outer chose its child 0 (the inner LOR), which chose a then b; then outer chose c.
    assert_eq!(h.chosen(), [0, 0, 1, 1]);
}

#[test]

fn a_nested_selector_does_not_make_the_outer_tick_a_child_twice() {
    // The outer's child 0 is a sequence whose inner LOR succeeds with its child 1 and whose
    // condition then fails; the outer must go on with its child 1, each child once.
    let text = "LOR 2\n- AND 2\n-- LOR 2\n--- A-a 0\n--- A-b 0\n-- C-x 0\n- A-c 0\n";
    let mut h = Bt::with(text, frozen(0.0), 1);
    h.tree.set_tables(vec![table(2, &[(0, &[1.0, 0.0])]), table(2, &[(0, &[0.0, 1.0])])]).unwrap();
    h.always("a", S).always("b", S).always("c", S);
    h.expect(S, &["b=S", "x=F", "c=S"]);
}

#[test]
fn a_fresh_copy_keeps_nothing_the_tree_learned_or_ran() {
    use rand::SeedableRng;
    let mut h = Bt::with("LOR 2\n- A-a 0\n- A-b 0\n", P, 1);
    h.always("a", R).always("b", F);
    h.expect(R, &["a=R"]);
    h.ctx.state = 1;
    h.expect(R, &["a=R"]);
    let learned = h.table(0);
    assert_eq!(learned.n_rows(), 1, "Q(0, a) was updated");
    let mut copy = h.tree.fresh(rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(1));
    assert_eq!(copy.tables()[0].n_rows(), 0, "a copy starts untrained");
    std::mem::swap(&mut h.tree, &mut copy);
    // Unseen states tie, so which child goes first depends on each tree's RNG; A-b fails.
    h.ctx.state = 2;
    assert_eq!(h.tick(), R);
    assert_eq!(h.get("a").progress_seen, [0, 1, 0], "A-a starts afresh in the copy");
    std::mem::swap(&mut h.tree, &mut copy);
    assert_eq!(h.table(0), learned, "ticking the copy changed nothing in the original");
    h.ctx.state = 3;
    assert_eq!(h.tick(), R);
    assert_eq!(h.get("a").progress_seen, [0, 1, 0, 2], "the original's A-a runs on");
}
