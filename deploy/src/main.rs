//! `alfd`: the command line of the project.

fn main() {
    eprintln!("alfd: not yet implemented");
    std::process::exit(2);
}
