//! docs/TRANSPORT.md states each payload's size, which sizes the shared memory a run maps.
//! This keeps the table in step with the structs: a field added to a message fails here
//! until the table says what it now costs.

use flockstep_proto::supervisor_to_world::Control;
use flockstep_proto::{Action, EpisodeBatch, EpisodeReport, JoinRequest, Observation};
use std::mem::size_of;

const TRANSPORT_MD: &str = include_str!("../../docs/TRANSPORT.md");

/// `n` with its thousands set apart by a space, as the docs write numbers.
fn grouped(n: usize) -> String {
    let digits = n.to_string();
    let mut out = String::new();
    for (i, digit) in digits.chars().enumerate() {
        if i > 0 && (digits.len() - i).is_multiple_of(3) {
            out.push(' ');
        }
        out.push(digit);
    }
    out
}

#[test]
fn grouping_sets_thousands_apart() {
    assert_eq!(grouped(8), "8");
    assert_eq!(grouped(784), "784");
    assert_eq!(grouped(19_464), "19 464");
    assert_eq!(grouped(1_234_567), "1 234 567");
}

#[test]
fn the_services_table_states_every_payload_size() {
    let stated = [
        format!("`Observation` ({})", grouped(size_of::<Observation>())),
        format!("`Action` ({})", grouped(size_of::<Action>())),
        format!(
            "`EpisodeBatch` ({}: up to {} `EpisodeReport`s of {})",
            grouped(size_of::<EpisodeBatch>()),
            flockstep_proto::EPISODE_BATCH,
            grouped(size_of::<EpisodeReport>())
        ),
        format!("`Control` ({})", grouped(size_of::<Control>())),
        format!("`JoinRequest` ({})", grouped(size_of::<JoinRequest>())),
    ];
    for text in stated {
        assert!(TRANSPORT_MD.contains(&text), "docs/TRANSPORT.md should say {text}");
    }
}
