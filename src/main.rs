//! The `polishbot` command line: wires the pipeline stages and files together.
// House rule: no function over 120 lines (threshold in clippy.toml); tests are exempt.
#![warn(clippy::too_many_lines)]
fn main() -> std::process::ExitCode {
    // A closed pipe on stdout (`polishbot plan ... | head -1`) ends the process quietly, as
    // for other command-line tools, instead of a panic inside println!.
    // SAFETY: called once at start-up, before any other thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    polishbot::cli::main()
}
