//! The `cloudgi` binary: the command line lives in the library (`src/cli/`).

fn main() {
    cloudgi::cli::main();
}
