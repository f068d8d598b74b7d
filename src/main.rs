//! The `aortagen` binary: a thin entry point over the library's command line.

/// mimalloc: burn's CPU backends allocate and free large tensors every step; glibc malloc
/// returns them to the OS and the kernel re-zeroes the pages each time (≈ 2.5× slower training).
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() -> std::process::ExitCode {
    match aortagen::cli::run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
