# A Rust build image with the layout of the public rust:*-slim-bookworm images
# (RUSTUP_HOME=/usr/local/rustup, CARGO_HOME=/usr/local/cargo, proxies in /usr/local/cargo/bin),
# for machines that cannot pull it. scripts/docker/base-images.sh builds it from
# debian:bookworm-slim and a context holding:
#   toolchain/   the host's rustup toolchain directory (documentation left out)
#   rustup       the host's rustup binary (the proxies cargo, rustc, … are links to it)
#   ca/          certificate authorities the host trusts beyond Debian's set, one PEM file
#                each (empty unless the host reaches crates.io through a TLS-inspecting
#                proxy); added to the image's trust store when ca-certificates is installed
# Toolchain and rustup arrive writable by all, as in the public image (a chmod here would copy
# them into a second layer).
# Cargo still fetches crates from crates.io inside builds that use this image.
FROM debian:bookworm-slim

ARG RUST_VERSION
ARG RUST_TOOLCHAIN=${RUST_VERSION}-x86_64-unknown-linux-gnu

COPY ca/ /usr/local/share/ca-certificates/
RUN apt-get update \
    && apt-get install -y --no-install-recommends ca-certificates gcc libc6-dev make pkg-config \
    && rm -rf /var/lib/apt/lists/*

ENV RUSTUP_HOME=/usr/local/rustup \
    CARGO_HOME=/usr/local/cargo \
    PATH=/usr/local/cargo/bin:$PATH \
    RUST_VERSION=${RUST_VERSION}

COPY toolchain /usr/local/rustup/toolchains/${RUST_TOOLCHAIN}
COPY rustup /usr/local/cargo/bin/rustup

RUN set -eu; \
    cd "$CARGO_HOME/bin"; \
    for tool in cargo cargo-clippy cargo-fmt clippy-driver rust-gdb rust-gdbgui rust-lldb rustc rustdoc rustfmt; do \
        ln rustup "$tool"; \
    done; \
    printf 'version = "12"\ndefault_toolchain = "%s"\nprofile = "minimal"\nauto_self_update = "disable"\n\n[overrides]\n' \
        "$RUST_TOOLCHAIN" >"$RUSTUP_HOME/settings.toml"; \
    chmod a+w "$RUSTUP_HOME" "$RUSTUP_HOME/toolchains" "$RUSTUP_HOME/settings.toml" "$CARGO_HOME" "$CARGO_HOME/bin"; \
    rustup --version; cargo --version; rustc --version

CMD ["bash"]
