//! The `polishbot` command line: wires the pipeline stages and files together.
fn main() -> std::process::ExitCode {
    polishbot::cli::main()
}
