#!/usr/bin/env bash
# Run a command inside a cached Debian 13 (trixie) root that has a real Blender (Debian packages
# Blender 4.3) with NumPy, Xvfb, xdotool and ImageMagick. The project is bind-mounted at /project.
#   bash scripts/real_blender.sh                 # build the root if needed, print Blender's version
#   bash scripts/real_blender.sh COMMAND ARGS... # run COMMAND inside the root, in /project
# Needs root (debootstrap and chroot). The root is cached outside the clone, in
# $RADIOSITY_REAL_BLENDER_ROOT (default /var/cache/radiosity-baker/trixie), so later runs reuse it;
# a stamp file marks a finished root, and a half-built one is rebuilt. The Debian mirror is the one
# this machine's apt already uses. First build: see README ("Test tiers") for the time and size.
# Any failure to build the root exits non-zero with a message: the UI tier is never skipped silently.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
root="${RADIOSITY_REAL_BLENDER_ROOT:-/var/cache/radiosity-baker/trixie}"
suite=trixie
packages="blender python3-numpy xvfb xauth xdotool imagemagick libegl1 libegl-mesa0"
stamp="$root/.radiosity-root-complete"
stamp_text="$suite: $packages"

die() { echo "real_blender.sh: $*" >&2; exit 1; }

[ "$(id -u)" -eq 0 ] || die "needs root (debootstrap and chroot); run it as root or with sudo"

mirror() {  # the first Debian mirror in this machine's apt sources
  local m=""
  if [ -f /etc/apt/sources.list ]; then
    m="$(awk '$1 == "deb" { for (i = 2; i <= NF; i++) if ($i ~ /^https?:\/\//) {
             print $i; exit } }' /etc/apt/sources.list)"
  fi
  if [ -z "$m" ]; then
    m="$(cat /etc/apt/sources.list.d/*.sources 2>/dev/null \
      | awk 'tolower($1) == "uris:" { for (i = 2; i <= NF; i++)
               if ($i ~ /^https?:\/\// && $i !~ /security/) { print $i; exit } }')"
  fi
  [ -n "$m" ] || die "no http(s) Debian mirror in /etc/apt/sources.list or" \
    "/etc/apt/sources.list.d/*.sources"
  echo "${m%/}"
}

stale_mounts() {  # binds left by a killed earlier run: never delete through them
  local m
  for m in $(awk -v r="$root/" 'index($2, r) == 1 { print $2 }' /proc/mounts | sort -r); do
    umount -l "$m" || die "cannot unmount $m left by an earlier run"
  done
  ! awk -v r="$root/" 'index($2, r) == 1 { found = 1 } END { exit !found }' /proc/mounts \
    || die "mounts remain under $root; unmount them before rebuilding"
}

build_root() {
  command -v debootstrap >/dev/null 2>&1 || {
    echo "real_blender.sh: installing debootstrap with apt-get" >&2
    apt-get update -qq || die "apt-get update failed: cannot install debootstrap"
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq debootstrap >/dev/null \
      || die "apt-get install debootstrap failed"
  }
  local m; m="$(mirror)"
  echo "real_blender.sh: building a Debian $suite root in $root from $m (one time; see README)" >&2
  local t0=$SECONDS
  stale_mounts
  rm -rf --one-file-system "$root"
  mkdir -p "$root"
  debootstrap --variant=minbase "$suite" "$root" "$m" >"$root.debootstrap.log" 2>&1 \
    || die "debootstrap $suite from $m into $root failed (log: $root.debootstrap.log)"
  echo "real_blender.sh: base system in $((SECONDS - t0)) s" >&2
  echo "deb $m $suite main" >"$root/etc/apt/sources.list"
  with_mounts chroot "$root" /bin/sh -c \
    "apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $packages" \
    >"$root.apt.log" 2>&1 \
    || die "installing '$packages' in $root failed (log: $root.apt.log)"
  chroot "$root" apt-get clean
  echo "$stamp_text" >"$stamp"
  echo "real_blender.sh: root ready in $((SECONDS - t0)) s, $(du -sh "$root" | cut -f1)" >&2
}

mounted=()
unmount_all() {
  local i
  for ((i = ${#mounted[@]} - 1; i >= 0; i--)); do
    umount -l "${mounted[$i]}" 2>/dev/null || true
  done
  mounted=()
}
bind() {  # bind SOURCE TARGET-INSIDE-ROOT
  mkdir -p "$root$2"
  mount --bind "$1" "$root$2" || die "mount --bind $1 $root$2 failed"
  mounted+=("$root$2")
}
with_mounts() {  # run a command with /proc, /dev, /dev/pts, /sys and the project mounted
  trap unmount_all EXIT
  bind /proc /proc
  bind /dev /dev
  bind /dev/pts /dev/pts
  bind /sys /sys
  bind "$here" /project
  # Blender lists mounted file systems through /etc/mtab, which debootstrap leaves out.
  [ -e "$root/etc/mtab" ] || ln -s /proc/self/mounts "$root/etc/mtab"
  [ -f /etc/resolv.conf ] && cp -L /etc/resolv.conf "$root/etc/resolv.conf" 2>/dev/null || true
  local rc=0
  "$@" || rc=$?
  unmount_all
  trap - EXIT
  return $rc
}

if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$stamp_text" ]; then
  mkdir -p "$(dirname "$root")" 2>/dev/null || die "cannot create $(dirname "$root") for the root"
  build_root
fi

[ $# -gt 0 ] || set -- blender --version
with_mounts chroot "$root" /usr/bin/env -i HOME=/root PATH=/usr/sbin:/usr/bin:/sbin:/bin \
  LANG=C.UTF-8 TERM=dumb ${RADIOSITY_UI_ENV:-} /bin/sh -c 'cd /project && exec "$@"' sh "$@"
