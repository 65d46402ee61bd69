//! The `omniwarp` command: a thin layer over the library; see `src/cli/`.

mod cli;

fn main() {
    cli::main()
}
