//! The `tessera` binary (the command line lives in the library: `tessera::run_cli`).

fn main() {
    tessera::run_cli();
}
