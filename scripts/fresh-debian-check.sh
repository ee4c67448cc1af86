#!/usr/bin/env bash
# The README's two commands on a minimal Debian 12, as a new user meets them.
#
# Bootstraps `debootstrap --variant=minbase bookworm` into a temporary directory, adds only
# git, make, sudo and ca-certificates, clones this repository (its committed HEAD) into it and
# runs `make demo` and `make test` there as root, each twice (the second run must install
# nothing). The chroot gets a hostname of its own that is not in its /etc/hosts, as in minimal
# images and containers. It reuses the host's apt sources and CA certificates so it reaches
# the same package archives; everything else comes from the repository's own set-up.
# Not part of `make test`: it needs root and debootstrap, and takes some minutes.
#
# usage: sudo scripts/fresh-debian-check.sh [--keep]   (--keep leaves the chroot for a look)
set -euo pipefail

[ "$(id -u)" = 0 ] || { echo "fresh-debian-check: run as root (it uses debootstrap, chroot and mounts)" >&2; exit 2; }
keep=0
[ "${1:-}" = "--keep" ] && keep=1
repo=$(cd "$(dirname "$0")/.." && git rev-parse --show-toplevel)
head=$(git -C "$repo" rev-parse --short HEAD)

if ! command -v debootstrap >/dev/null; then
  echo "fresh-debian-check: installing debootstrap"
  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq debootstrap >/dev/null
fi

# the host's Debian mirror: deb822 sources first, then the one-line format
mirror=$(sed -n 's/^URIs:[[:space:]]*\([^[:space:]]*\/debian\)[[:space:]]*$/\1/p' /etc/apt/sources.list.d/*.sources 2>/dev/null | head -n 1)
[ -n "$mirror" ] || mirror=$(awk '$1 == "deb" && $3 == "bookworm" {print $2; exit}' /etc/apt/sources.list 2>/dev/null)
[ -n "$mirror" ] || mirror=http://deb.debian.org/debian

root=$(mktemp -d /var/tmp/bmtree-fresh.XXXXXX)
log=$root.log
mounted=()
cleanup() {
  # processes left running inside the chroot (a test's daemon, an interrupted run)
  for p in /proc/[0-9]*; do
    [ "$(readlink "$p/root" 2>/dev/null)" = "$root" ] && kill -9 "${p#/proc/}" 2>/dev/null || true
  done
  for ((i=${#mounted[@]}-1; i>=0; i--)); do umount -l "${mounted[i]}" 2>/dev/null || true; done
  if [ "$keep" = 1 ]; then echo "fresh-debian-check: chroot kept at $root"; else rm -rf "$root"; fi
}
trap cleanup EXIT
mnt() { mount "$@"; mounted+=("${@: -1}"); }

step() { printf '\n=== %s\n' "$*"; }
step "debootstrap --variant=minbase bookworm $root ($mirror)"
t0=$(date +%s)
debootstrap --variant=minbase bookworm "$root" "$mirror" >"$log" 2>&1 || { tail -20 "$log"; exit 1; }
echo "done in $(( $(date +%s) - t0 )) s"

# the host's apt sources, apt settings and CA certificates; a hosts file without our hostname
rm -f "$root/etc/apt/sources.list"
cp -a /etc/apt/sources.list "$root/etc/apt/" 2>/dev/null || true
mkdir -p "$root/etc/apt/sources.list.d" "$root/etc/apt/apt.conf.d"
for f in /etc/apt/sources.list.d/*.sources /etc/apt/sources.list.d/*.list; do
  [ -f "$f" ] && grep -q 'debian' "$f" && cp -a "$f" "$root/etc/apt/sources.list.d/"
done
cp -a /etc/apt/apt.conf.d/. "$root/etc/apt/apt.conf.d/" 2>/dev/null || true
mkdir -p "$root/usr/local/share/ca-certificates"
cp -a /usr/local/share/ca-certificates/. "$root/usr/local/share/ca-certificates/" 2>/dev/null || true
mkdir -p "$root/etc/ssl/certs"
cp -aL /etc/ssl/certs/ca-certificates.crt "$root/etc/ssl/certs/" 2>/dev/null || true
cp -L /etc/resolv.conf "$root/etc/resolv.conf"
printf '127.0.0.1\tlocalhost\n::1\tlocalhost ip6-localhost ip6-loopback\n' >"$root/etc/hosts"

# the chroot's / is a mount point of its own, as on a real machine: `ip netns exec` remounts /
# as a slave in its new mount namespace, which fails with EINVAL on a plain directory
mnt --bind "$root" "$root"
mnt -t proc proc "$root/proc"
mnt -t sysfs sys "$root/sys"
mnt --bind /dev "$root/dev"
mnt -t devpts devpts "$root/dev/pts" -o newinstance,ptmxmode=0666 2>/dev/null || mnt --bind /dev/pts "$root/dev/pts"
mnt -t tmpfs tmpfs "$root/tmp"

# a new user's shell in the chroot: a clean environment, a hostname that resolves nowhere
in_chroot() {
  unshare --uts chroot "$root" /usr/bin/env -i HOME=/root TERM=dumb LANG=C.UTF-8 \
    PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin \
    ${http_proxy:+http_proxy=$http_proxy} ${https_proxy:+https_proxy=$https_proxy} \
    /bin/bash -c 'hostname bmtree-fresh-check && cd /root && '"$1"
}

step "apt-get install git make sudo ca-certificates (the README's prerequisite line)"
in_chroot 'apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq git make sudo ca-certificates >/dev/null && update-ca-certificates >/dev/null && echo ok'

step "git clone (HEAD $head)"
git clone -q "$repo" "$root/root/bmtree"
git -C "$root/root/bmtree" log --oneline -1

results=()
run() {  # name, command
  step "$1"
  local t0 rc out
  t0=$(date +%s)
  set +e
  in_chroot "cd bmtree && $2" 2>&1 | tee "$root/root/$(echo "$1" | tr ' ' '_').log"
  rc=${PIPESTATUS[0]}
  set -e
  local secs=$(( $(date +%s) - t0 ))
  local installed="installed nothing"
  grep -q '^setup: ' "$root/root/$(echo "$1" | tr ' ' '_').log" && installed="installed: $(grep '^setup: ' "$root/root/$(echo "$1" | tr ' ' '_').log" | tr '\n' ' ')"
  results+=("$(printf '%-18s exit %-3s %5d s   %s' "$1" "$rc" "$secs" "$installed")")
}
run "make demo"   "make demo"
run "make test"   "make test"
run "make demo again" "make demo"
run "make test again" "make test"

step "summary (minimal Debian 12, HEAD $head, hostname not in /etc/hosts)"
printf '%s\n' "${results[@]}"
failed=0
for r in "${results[@]}"; do case "$r" in *"exit 0 "*) ;; *) failed=1 ;; esac; done
for r in "${results[@]:2}"; do case "$r" in *"installed nothing"*) ;; *) failed=1 ;; esac; done
[ "$failed" = 0 ] && echo "fresh-debian-check: PASS" || echo "fresh-debian-check: FAIL"
exit "$failed"
