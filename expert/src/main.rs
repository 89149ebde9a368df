//! `alfd-expert`: the expert process.

fn main() {
    eprintln!("alfd-expert: not yet implemented");
    std::process::exit(2);
}
