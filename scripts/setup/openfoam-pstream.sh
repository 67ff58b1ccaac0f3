#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# Copyright (C) fiberform contributors
#
# Rebuild OpenFOAM v1912's MPI layer libPstream.so (4 source files of Debian's source package, in
# .deps/openfoam/src/Pstream/mpi) with ONE change: UPstream::init splits MPI_COMM_WORLD by
# MPI_APPNUM right after MPI_Init and uses this program's part as OpenFOAM's world. A parallel
# OpenFOAM solver can then share one mpirun with a partner program (MPMD: fiberdem), whose first
# collective on MPI_COMM_WORLD must be the matching split (coupling/layer start_world()).
# Alone (no MPMD) the split holds every rank: results are those of Debian's library.
# The split communicator is exported as the C symbol `fiberform_pstream_world` (MPI_Comm): the
# coupled fiberPimpleFoam -parallel finds it with dlsym (its absence = stock library: refused) and
# connects to the fibers over it (coupling/layer join_world()), so MPI_COMM_WORLD is split once.
#
# Nothing of the installed OpenFOAM changes: the library goes to a project directory and is used
# through LD_LIBRARY_PATH for coupled runs only:
#   LD_LIBRARY_PATH=$FIBERFORM_PSTREAM_DIR mpirun -np A fiberdem ... : -np B solver -parallel ...
#
# Usage: scripts/setup/openfoam-pstream.sh
#   FIBERFORM_PSTREAM_DIR  output directory (default <repo>/.deps/openfoam-pstream)
# Exit:  0 done (or up to date), 2 a precondition is missing, 1 the build or a patch check failed.
# Docs:  docs/coupling/launch.md ("Parallel fluid")
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
readonly root
readonly src=$root/.deps/openfoam/src/Pstream/mpi
readonly out=${FIBERFORM_PSTREAM_DIR:-$root/.deps/openfoam-pstream}
readonly of_src=$root/.deps/openfoam/src
readonly stamp_text="v1912 APPNUM split 2 (exported fiberform_pstream_world)"

say() { printf 'openfoam-pstream: %s\n' "$*" >&2; }
die() { say "ERROR: $*"; exit 2; }

[[ -f $src/UPstream.C && -d $of_src/OpenFOAM/lnInclude ]] ||
    die "OpenFOAM sources missing in $of_src (run scripts/setup/openfoam-headers.sh first)"
command -v mpicxx >/dev/null || die "mpicxx not found (install libopenmpi-dev: scripts/setup/debian-packages.sh)"

if [[ -f $out/libPstream.so && -f $out/.complete && $(<"$out/.complete") == "$stamp_text" ]]; then
    exit 0
fi

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cp "$src"/*.C "$src"/*.H "$work"/

# --- the patch: two places in UPstream.C use MPI_COMM_WORLD as OpenFOAM's world ----------------
# (1) init(): size and rank of the world -> split first, then size and rank of our part
# (2) allocatePstreamCommunicator(): communicator 0 (worldComm) -> our part
# Each substitution must happen exactly once; anything else means a different source: stop.
patch_once() {  # file, perl substitution, description
    local before after
    before=$(md5sum <"$1")
    perl -0pi -e "$2" "$1"
    after=$(md5sum <"$1")
    [[ $before != "$after" ]] || { say "patch did not apply: $3"; exit 1; }
}
u=$work/UPstream.C
[[ $(grep -c 'MPI_COMM_WORLD' "$u") -eq 6 ]] || { say "unexpected UPstream.C (MPI_COMM_WORLD count)"; exit 1; }
patch_once "$u" 's/(\n#include "PstreamGlobals.H"\n)/$1\n\/\/ fiberform: this program'"'"'s part of an MPMD world (split by MPI_APPNUM)\nextern \"C\" { MPI_Comm fiberform_pstream_world = MPI_COMM_NULL; }\n/' "declaration"
patch_once "$u" 's/    MPI_Comm_size\(MPI_COMM_WORLD, &numprocs\);\n    MPI_Comm_rank\(MPI_COMM_WORLD, &myRank\);\n/    \/\/ fiberform: split MPI_COMM_WORLD by MPI_APPNUM, our first collective on it (coupling\/layer)\n    {\n        int worldRank = 0, appFlag = 0;\n        int* appnum = nullptr;\n        MPI_Comm_rank(MPI_COMM_WORLD, &worldRank);\n        MPI_Comm_get_attr(MPI_COMM_WORLD, MPI_APPNUM, &appnum, &appFlag);\n        MPI_Comm_split\n        (\n            MPI_COMM_WORLD, (appFlag && appnum) ? *appnum : 0, worldRank, &fiberform_pstream_world\n        );\n    }\n    MPI_Comm_size(fiberform_pstream_world, &numprocs);\n    MPI_Comm_rank(fiberform_pstream_world, &myRank);\n/' "init"
patch_once "$u" 's/MPICommunicators_\[index\] = MPI_COMM_WORLD;\n        MPI_Comm_group\(MPI_COMM_WORLD,/MPICommunicators_[index] = fiberform_pstream_world;\n        MPI_Comm_group(fiberform_pstream_world,/' "worldComm"
[[ $(grep -c 'fiberform_pstream_world' "$u") -eq 6 ]] || { say "patch check failed (fiberform_pstream_world count)"; exit 1; }

# --- compile with Debian's ABI flags (docs/setup/openfoam-headers.md) ---------------------------
flags=(-std=c++14 -m64 -O3 -fPIC -Wno-attributes -DOPENFOAM=1912 -DWM_DP -DWM_LABEL_SIZE=32 -DNoRepository
       -ftemplate-depth-100 -I"$work" -I"$of_src/OpenFOAM/lnInclude" -I"$of_src/OSspecific/POSIX/lnInclude")
for f in UPstream UOPwrite UIPread PstreamGlobals; do
    mpicxx "${flags[@]}" -c "$work/$f.C" -o "$work/$f.o"
done
mpicxx -shared -o "$work/libPstream.so" "$work"/UPstream.o "$work"/UOPwrite.o "$work"/UIPread.o \
    "$work"/PstreamGlobals.o
nm -D --defined-only "$work/libPstream.so" | grep -q ' fiberform_pstream_world$' ||
    { say "patch check failed (fiberform_pstream_world not exported)"; exit 1; }

mkdir -p "$out"
mv "$work/libPstream.so" "$out/libPstream.so.tmp"
mv "$out/libPstream.so.tmp" "$out/libPstream.so"
printf '%s\n' "$stamp_text" >"$out/.complete.tmp"
mv "$out/.complete.tmp" "$out/.complete"
say "built $out/libPstream.so (use with LD_LIBRARY_PATH for coupled parallel runs only)"
