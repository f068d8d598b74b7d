# Sourced by the experiment scripts under docs/ (bash): moves to the repository root, sets
# `bin` to $AORTAGEN when given, else to a release binary it builds, and defines `timed`.

cd "$(dirname "${BASH_SOURCE[0]}")/.."
if [ -n "${AORTAGEN:-}" ]; then
    bin="$AORTAGEN"
else
    cargo build --release --locked --quiet
    bin="${CARGO_TARGET_DIR:-target}/release/aortagen"
fi

timed() { # LABEL COMMAND...: runs COMMAND, then prints its wall time and peak RSS
    local label="$1"
    shift
    /usr/bin/time -f "$label: %e s, peak RSS %M KiB" "$@"
}
