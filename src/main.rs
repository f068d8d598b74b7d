//! The `aortagen` binary: a thin entry point over the library's command line.

fn main() -> std::process::ExitCode {
    match aortagen::cli::run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
