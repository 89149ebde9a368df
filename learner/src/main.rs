//! `alfd-learner`: the learner process.

fn main() {
    eprintln!("alfd-learner: not yet implemented");
    std::process::exit(2);
}
