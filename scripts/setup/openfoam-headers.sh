#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# Copyright (C) fiberform contributors
#
# Fetch the OpenFOAM headers that match the installed Debian binary package.
#
# Debian's openfoam/libopenfoam packages ship binaries and libraries but no headers and no wmake.
# This script takes them from Debian's source package of exactly the installed version, unpacks
# only src/ and wmake/ into .deps/openfoam/, applies Debian's patches that touch those trees and
# creates the lnInclude header links. Nothing of OpenFOAM is compiled.
#
# Usage: scripts/setup/openfoam-headers.sh      (from anywhere; paths are relative to the repo)
# Exit:  0 done (or already up to date), 2 a precondition is missing (message says what to do).
# Docs:  docs/setup/openfoam-headers.md
set -euo pipefail

readonly want_src=1912.200626-1          # Debian source version the project is pinned to
readonly pkg=openfoam
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
readonly root
readonly deps=$root/.deps
readonly dest=$deps/openfoam
readonly download=$deps/openfoam-download
readonly src_list=/etc/apt/sources.list.d/fiberform-src.sources
readonly debian_list=/etc/apt/sources.list.d/debian.sources

say() { printf 'openfoam-headers: %s\n' "$*" >&2; }
die() { say "ERROR: $*"; exit 2; }

# --- 1. installed binary version --------------------------------------------------------------
status=$(dpkg-query -W -f='${db:Status-Status} ${Version}' "$pkg" 2>/dev/null || true)
[[ $status == installed\ * ]] ||
    die "package '$pkg' is not installed (run scripts/setup/debian-packages.sh first)"
bin_ver=${status#installed }
src_ver=${bin_ver%+b[0-9]*}              # strip a binNMU suffix: 1912.200626-1+b1 -> 1912.200626-1
[[ $src_ver == "$want_src" ]] ||
    die "installed $pkg is $bin_ver, fiberform needs $want_src (or a binNMU $want_src+bN)"

# --- 2. fast path: already done for this version ----------------------------------------------
if [[ -f $dest/.complete && $(<"$dest/.complete") == "$want_src" ]]; then
    exit 0
fi

# --- 3. make sure apt knows the source package (deb-src entry for the same archive) -----------
have_source() {
    apt-cache showsrc --only-source "$pkg" 2>/dev/null | grep -qx "Version: $want_src"
}
# The archive that provided the installed binary, from apt's own policy table: "URI SUITE/COMPONENT".
archive_of_installed() {
    apt-cache policy "$pkg" 2>/dev/null | awk -v v="$bin_ver" '
        /^ +(\*\*\* )?[^ ]+ [0-9]+$/ { cur = ($1 == "***") ? $2 : $1; next }
        cur == v && $2 ~ /^(https?|file|cdrom):/ { print $2, $3; exit }'
}
if ! have_source; then
    if [[ -r $debian_list ]]; then
        # deb822 (Debian 12 container images): the same stanzas with Types: deb-src.
        list_file=$src_list
        new_list=$(awk '/^Types:/ { print "Types: deb-src"; next } { print }' "$debian_list")
        origin=$debian_list
    else
        # one-line format (/etc/apt/sources.list, Debian installer): derive the entry from the
        # archive apt installed the binary package from.
        read -r uri suite_comp < <(archive_of_installed) ||
            die "cannot tell which archive provided $pkg $bin_ver (apt-cache policy $pkg);
add a deb-src line for it, run apt-get update, rerun"
        list_file=${src_list%.sources}.list
        new_list="deb-src $uri ${suite_comp%%/*} ${suite_comp#*/}"
        origin="apt-cache policy $pkg"
    fi
    if [[ $(id -u) -ne 0 ]]; then
        die "apt has no deb-src entry for $pkg. As root, write to $list_file:
$new_list
then run apt-get update and rerun $0"
    fi
    say "adding $list_file (deb-src for the archive of $pkg, from $origin) and running apt-get update"
    printf '# Written by fiberform scripts/setup/openfoam-headers.sh: source packages of the\n# archive that provides openfoam (from %s), needed for OpenFOAM headers.\n%s\n' \
        "$origin" "$new_list" >"$list_file"
    apt-get update -qq
    have_source || die "apt still does not offer source package $pkg=$want_src after adding $list_file"
fi

# --- 4. download (apt verifies the hashes from the signed Release file) -----------------------
mkdir -p "$download"
say "downloading source package $pkg=$want_src into ${download#"$root"/}"
(cd "$download" && apt-get source -qq --download-only "$pkg=$want_src")
upstream=${want_src%-*}
orig=$(compgen -G "$download/${pkg}_${upstream}.orig.tar.*" | head -n1 || true)
debtar=$(compgen -G "$download/${pkg}_${want_src}.debian.tar.*" | head -n1 || true)
[[ -n $orig && -n $debtar ]] || die "download incomplete: no orig or debian tarball in $download"

# --- 5. unpack src/ and wmake/ into a temporary directory, then rename ------------------------
tmp=$(mktemp -d "$deps/openfoam.tmp.XXXXXX")
trap 'rm -rf "$tmp"' EXIT
chmod 755 "$tmp"                         # mktemp makes it 0700; the result is shared read-only
top=$(tar -tf "$orig" | head -n1 | cut -d/ -f1 || true)
[[ -n $top ]] || die "cannot read $orig"
say "unpacking $top/{src,wmake} from $(basename "$orig")"
tar -xf "$orig" -C "$tmp" --no-same-owner --strip-components=1 "$top/src" "$top/wmake"

# Debian's patches (quilt series) that touch src/ or wmake/, so headers match the binaries.
mkdir "$tmp/.debian"
tar -xf "$debtar" -C "$tmp/.debian" --no-same-owner debian/patches
series=$tmp/.debian/debian/patches/series
if [[ -f $series ]]; then
    while read -r patch_name _; do
        [[ -z $patch_name || $patch_name == \#* ]] && continue
        patch_file=$tmp/.debian/debian/patches/$patch_name
        # Only patches whose every target lies in src/ or wmake/; others concern parts we skip.
        if grep -E '^\+\+\+ ' "$patch_file" | awk '{print $2}' | cut -d/ -f2- |
            grep -qvE '^(src|wmake)/'; then
            say "skipping Debian patch $patch_name (it touches files outside src/ and wmake/)"
            continue
        fi
        say "applying Debian patch $patch_name"
        patch -s -p1 -d "$tmp" <"$patch_file"
    done <"$series"
fi
rm -rf "$tmp/.debian"

# lnInclude links (relative symlinks) for every library directory, as wmake would create them.
# wmakeLnInclude reports each directory on stderr: keep that in a log, show it only on failure.
say "creating lnInclude links"
find "$tmp/src" -type f -path '*/Make/files' -printf '%h\n' | sed 's#/Make$##' |
    xargs -P "$(nproc)" -I{} "$tmp/wmake/wmakeLnInclude" -s {} >"$tmp/lnInclude.log" 2>&1 ||
    { cat "$tmp/lnInclude.log" >&2; die "wmakeLnInclude failed"; }
rm -f "$tmp/lnInclude.log"
[[ -f $tmp/src/finiteVolume/lnInclude/fvCFD.H ]] ||
    die "lnInclude creation failed (no fvCFD.H)"

printf '%s\n' "$want_src" >"$tmp/.complete"
if [[ -e $dest ]]; then
    old=$(mktemp -d "$deps/openfoam.old.XXXXXX")
    mv -T "$dest" "$old/openfoam"
    mv -T "$tmp" "$dest"
    rm -rf "$old"
else
    mv -T "$tmp" "$dest"
fi
trap - EXIT
say "done: headers in ${dest#"$root"/}/src (version $want_src)"
