//! The `gpmm` command-line program.
fn main() -> std::process::ExitCode {
    gpmm_host::cli::main()
}
