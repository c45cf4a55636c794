use flockstep_world::Scenario;
use flockstep_proto::{Pose, Height, Heading};
#[test]
fn scratch() {
    for n in ["s1","s2","s3"] {
        match Scenario::resolve(n) {
            Ok(s) => {
                println!("{n} ok");
                for u in 0..s.n_routes() { for k in 0..s.n_targets() {
                    println!("  UAV{} T{}: {:?}", u+1, k+1, s.poses_seeing(u,k).iter().map(|p| p.to_string()).collect::<Vec<_>>());
                }}
            }
            Err(e) => println!("{n}: {e}"),
        }
    }
    let s = Scenario::builtin("s2").unwrap();
    println!("{:?}", s.visible_cells(0, Pose::new(5, Height::High, Heading::E)));
    println!("{}", s.map().to_text());
}
