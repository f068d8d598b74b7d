#!/usr/bin/env bash
# Provides the public base images the project's Dockerfiles start FROM:
#
#   debian:bookworm-slim       runtime stage of every image
#   rust:1.95-slim-bookworm    build stage of the service and of the S3 server
#
# Each is kept when present, else pulled (60 s at most), else built here and tagged under the
# public name, so the Dockerfiles stay the same on machines that reach a registry:
#   debian:bookworm-slim     debootstrap --variant=minbase from deb.debian.org, slimmed the
#                            way the public image is (no docs, man pages or locales; apt lists
#                            removed), imported with `docker import`
#   rust:1.95-slim-bookworm  deploy/base/rust.Dockerfile: that Debian image, gcc, make,
#                            pkg-config and the host's rustup toolchain 1.95 under the public
#                            image's layout (/usr/local/cargo, /usr/local/rustup)
#
#   scripts/docker/base-images.sh [--rebuild]    --rebuild: build both here even when present
# Needs root for debootstrap; installs debootstrap with apt when missing.
set -euo pipefail
source "$(dirname "$0")/lib.sh"

DEBIAN_IMAGE=debian:bookworm-slim
RUST_IMAGE=rust:1.95-slim-bookworm
RUST_VERSION_PREFIX=1.95.
DEBIAN_MIRROR="${AORTAGEN_DEBIAN_MIRROR:-http://deb.debian.org/debian}"
DEBIAN_SECURITY_MIRROR="${AORTAGEN_DEBIAN_SECURITY_MIRROR:-http://deb.debian.org/debian-security}"
PULL_TIMEOUT="${AORTAGEN_PULL_TIMEOUT:-60}"

rebuild=0
case "${1:-}" in
    --rebuild) rebuild=1 ;;
    "") ;;
    *) die "usage: $0 [--rebuild]" ;;
esac

engine_up || die "no Docker engine answers; run scripts/docker/engine.sh first"

image_present() { docker image inspect "$1" >/dev/null 2>&1; }

# try_pull IMAGE: 0 when the registry gave it.
try_pull() {
    local image="$1" out
    say "$image: trying docker pull (at most ${PULL_TIMEOUT} s)"
    if out="$(timeout "$PULL_TIMEOUT" docker pull -q "$image" 2>&1)"; then
        say "$image: pulled"
        return 0
    fi
    say "$image: pull failed: $(printf '%s' "$out" | tail -n 1)"
    return 1
}

# --- debian:bookworm-slim ------------------------------------------------------------------
build_debian() {
    [[ $EUID -eq 0 ]] || die "building $DEBIAN_IMAGE with debootstrap needs root"
    if ! command -v debootstrap >/dev/null; then
        say "installing debootstrap with apt"
        apt-get update -qq
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends debootstrap >/dev/null
    fi
    local rootfs="$AORTAGEN_DOCKER_HOME/rootfs/bookworm" logfile="$AORTAGEN_DOCKER_HOME/debootstrap.log"
    rm -rf "$rootfs"
    mkdir -p "$rootfs"
    say "$DEBIAN_IMAGE: debootstrap --variant=minbase bookworm from $DEBIAN_MIRROR (log: $logfile; about 2-3 min)"
    local t0
    t0="$(now)"
    debootstrap --variant=minbase bookworm "$rootfs" "$DEBIAN_MIRROR" >"$logfile" 2>&1 \
        || { tail -n 20 "$logfile" >&2; die "debootstrap failed; see $logfile"; }

    # Sources: the release, its updates and its security fixes, as in the public image.
    rm -f "$rootfs/etc/apt/sources.list"
    cat >"$rootfs/etc/apt/sources.list.d/debian.sources" <<EOF
Types: deb
URIs: $DEBIAN_MIRROR
Suites: bookworm bookworm-updates
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg

Types: deb
URIs: $DEBIAN_SECURITY_MIRROR
Suites: bookworm-security
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg
EOF
    # Slim: packages installed later leave out documentation, manual pages and translations.
    cat >"$rootfs/etc/dpkg/dpkg.cfg.d/slim" <<'EOF'
path-exclude /usr/share/doc/*
path-include /usr/share/doc/*/copyright
path-exclude /usr/share/man/*
path-exclude /usr/share/info/*
path-exclude /usr/share/locale/*
path-include /usr/share/locale/locale.alias
path-exclude /usr/share/lintian/*
path-exclude /usr/share/groff/*
EOF
    cat >"$rootfs/etc/apt/apt.conf.d/slim" <<'EOF'
// Container image: no package cache kept, no translated indexes, no suggestions kept.
DPkg::Post-Invoke { "rm -f /var/cache/apt/archives/*.deb /var/cache/apt/archives/partial/*.deb /var/cache/apt/*.bin || true"; };
APT::Update::Post-Invoke { "rm -f /var/cache/apt/archives/*.deb /var/cache/apt/archives/partial/*.deb /var/cache/apt/*.bin || true"; };
Dir::Cache::pkgcache "";
Dir::Cache::srcpkgcache "";
Acquire::Languages "none";
Acquire::GzipIndexes "true";
Acquire::CompressionTypes::Order:: "gz";
APT::AutoRemove::SuggestsImportant "false";
EOF
    # Security and point-release updates published since the release.
    say "$DEBIAN_IMAGE: applying bookworm-updates and bookworm-security"
    chroot "$rootfs" apt-get update -qq >>"$logfile" 2>&1 \
        && DEBIAN_FRONTEND=noninteractive chroot "$rootfs" apt-get upgrade -y -qq >>"$logfile" 2>&1 \
        || { tail -n 20 "$logfile" >&2; die "apt-get upgrade in the new root failed; see $logfile"; }
    # What the slim image does not carry, and what belongs to this host.
    find "$rootfs/usr/share/doc" -mindepth 1 -not -name copyright -not -type d -delete
    find "$rootfs/usr/share/doc" -mindepth 1 -type d -empty -delete
    rm -rf "$rootfs"/usr/share/{man,info,lintian,groff}/* "$rootfs"/var/lib/apt/lists/* \
        "$rootfs"/var/cache/apt/* "$rootfs"/var/cache/debconf/*-old "$rootfs"/var/lib/dpkg/*-old \
        "$rootfs"/tmp/* "$rootfs"/var/tmp/* "$rootfs"/var/log/apt/* "$rootfs"/var/log/bootstrap.log
    find "$rootfs/usr/share/locale" -mindepth 1 -maxdepth 1 -not -name locale.alias -exec rm -rf {} +
    find "$rootfs/var/log" -type f -exec truncate -s 0 {} +
    : >"$rootfs/etc/resolv.conf"
    : >"$rootfs/etc/machine-id"
    rm -f "$rootfs/etc/hostname"

    say "$DEBIAN_IMAGE: importing $(du -sh "$rootfs" | cut -f1) root file system"
    tar -C "$rootfs" --numeric-owner --xattrs --exclude='./dev/*' --exclude='./proc/*' --exclude='./sys/*' -cf - . \
        | docker import --change 'CMD ["bash"]' \
            --change 'LABEL org.opencontainers.image.description="Debian bookworm minbase, built locally by debootstrap"' \
            - "$DEBIAN_IMAGE" >/dev/null
    rm -rf "$rootfs"
    say "$DEBIAN_IMAGE: built locally in $(elapsed $(($(now) - t0))) ($(docker image inspect -f '{{.Size}}' "$DEBIAN_IMAGE" | numfmt --to=iec))"
}

# --- rust:1.95-slim-bookworm ---------------------------------------------------------------
# extra_ca_certificates DIR: writes into DIR (one .crt each) the certificate authorities the
# host trusts beyond those Debian's ca-certificates ships: on a network that reaches crates.io
# only through a TLS-inspecting proxy, cargo in the build image must trust its CA as the host
# does. AORTAGEN_EXTRA_CA_CERTS=FILE takes the PEM file's certificates instead; =none, none.
extra_ca_certificates() {
    local dir="$1" source="${AORTAGEN_EXTRA_CA_CERTS:-}" work
    [[ "$source" == none ]] && { say "extra CA certificates: none (AORTAGEN_EXTRA_CA_CERTS=none)"; return; }
    work="$(mktemp -d)"
    if [[ -n "$source" ]]; then
        [[ -r "$source" ]] || die "AORTAGEN_EXTRA_CA_CERTS=$source is not a readable file"
        awk -v out="$work/cert" '/BEGIN CERTIFICATE/ { n++ } n { print > (out n ".pem") }' "$source"
    else
        local bundle=/etc/ssl/certs/ca-certificates.crt shipped=/usr/share/ca-certificates
        if [[ ! -r "$bundle" || ! -d "$shipped" ]] || ! command -v openssl >/dev/null; then
            say "extra CA certificates: none looked for (no $bundle, $shipped or openssl on the host)"
            rm -rf "$work"
            return
        fi
        local known="$work/known" pem fingerprint
        find "$shipped" -name '*.crt' -exec sh -c 'for f; do openssl x509 -noout -fingerprint -sha256 -in "$f"; done' sh {} + \
            | sort -u >"$known"
        awk -v out="$work/host" '/BEGIN CERTIFICATE/ { n++ } n { print > (out n ".pem") }' "$bundle"
        for pem in "$work"/host*.pem; do
            [[ -e "$pem" ]] || continue
            fingerprint="$(openssl x509 -noout -fingerprint -sha256 -in "$pem")"
            if ! grep -qxF "$fingerprint" "$known"; then
                mv "$pem" "$work/cert$(basename "$pem" .pem | tr -dc 0-9).pem"
            fi
        done
    fi
    local count=0 pem
    for pem in "$work"/cert*.pem; do
        [[ -e "$pem" ]] || continue
        count=$((count + 1))
        cp "$pem" "$dir/host-extra-$count.crt"
        say "extra CA certificate trusted in $RUST_IMAGE: $(openssl x509 -noout -subject -in "$pem")"
    done
    [[ $count -gt 0 ]] || say "extra CA certificates: none (the host trusts only Debian's set)"
    rm -rf "$work"
}

build_rust() {
    command -v rustup >/dev/null || die "building $RUST_IMAGE needs the host's rustup with a 1.95 toolchain"
    # The host toolchain that is 1.95: the one named 1.95.0 if installed, else the default.
    local sysroot="" candidate version
    for candidate in 1.95.0 1.95 stable ""; do
        if [[ -n "$candidate" ]]; then
            version="$(RUSTUP_AUTO_INSTALL=0 rustup run "$candidate" rustc --version 2>/dev/null || true)"
        else
            version="$(rustc --version 2>/dev/null || true)"
        fi
        if [[ "$version" == "rustc $RUST_VERSION_PREFIX"* ]]; then
            if [[ -n "$candidate" ]]; then
                sysroot="$(RUSTUP_AUTO_INSTALL=0 rustup run "$candidate" rustc --print sysroot)"
            else
                sysroot="$(rustc --print sysroot)"
            fi
            break
        fi
    done
    [[ -n "$sysroot" ]] || die "no rustup toolchain of version ${RUST_VERSION_PREFIX}x on this host (rustup toolchain list: $(rustup toolchain list | tr '\n' ' '))"
    local rust_version
    rust_version="$(awk '{print $2}' <<<"$version")"
    local rustup_bin
    rustup_bin="$(readlink -f "$(command -v rustup)")"

    local context="$AORTAGEN_DOCKER_HOME/contexts/rust"
    say "$RUST_IMAGE: context from $sysroot ($version), documentation left out"
    rm -rf "$context"
    mkdir -p "$context/toolchain"
    tar -C "$sysroot" --exclude=./share/doc -cf - . | tar -C "$context/toolchain" -xf -
    # The rust-docs component's files are left out: drop it from the toolchain's component list.
    if [[ -f "$context/toolchain/lib/rustlib/components" ]]; then
        sed -i '/^rust-docs-/d' "$context/toolchain/lib/rustlib/components"
        rm -f "$context/toolchain/lib/rustlib/manifest-rust-docs-"*
    fi
    cp "$rustup_bin" "$context/rustup"
    mkdir -p "$context/ca"
    extra_ca_certificates "$context/ca"
    chmod -R a+w "$context"

    local t0
    t0="$(now)"
    say "$RUST_IMAGE: docker build -f deploy/base/rust.Dockerfile (RUST_VERSION=$rust_version)"
    docker_build "$RUST_IMAGE" "$AORTAGEN_ROOT/deploy/base/rust.Dockerfile" "$context" \
        --build-arg "RUST_VERSION=$rust_version" >"$AORTAGEN_DOCKER_HOME/rust-image.log" 2>&1 \
        || { tail -n 30 "$AORTAGEN_DOCKER_HOME/rust-image.log" >&2; die "building $RUST_IMAGE failed; see $AORTAGEN_DOCKER_HOME/rust-image.log"; }
    rm -rf "$context"
    local network_args
    mapfile -t network_args < <(run_network_args)
    say "$RUST_IMAGE: built locally in $(elapsed $(($(now) - t0))) ($(docker run --rm "${network_args[@]}" "$RUST_IMAGE" rustc --version))"
}

provide() {
    local image="$1" builder="$2"
    if [[ $rebuild -eq 0 ]] && image_present "$image"; then
        say "$image: present ($(docker image inspect -f '{{.Id}}' "$image" | cut -c1-19)), kept"
        return
    fi
    if [[ $rebuild -eq 0 ]] && try_pull "$image"; then
        return
    fi
    say "$image: building it here"
    "$builder"
}

provide "$DEBIAN_IMAGE" build_debian
provide "$RUST_IMAGE" build_rust
say "base images ready: $DEBIAN_IMAGE, $RUST_IMAGE"
