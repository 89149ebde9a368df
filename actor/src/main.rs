//! `alfd-actor`: the actor process.

fn main() {
    eprintln!("alfd-actor: not yet implemented");
    std::process::exit(2);
}
