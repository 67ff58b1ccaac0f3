# SPDX-License-Identifier: GPL-3.0-or-later
# Script mode (cmake -DSRC=<source dir> -DOUT=<file> -P WriteRevision.cmake), run at every build by
# the target fiberform_revision: writes OUT (build/REVISION) with the commit the compiled sources
# come from, `git rev-parse --short HEAD`, plus "-dirty" when a tracked file under the compiled
# trees (liggghts-fiber-style, coupling, cmake, CMakeLists.txt) differs from that commit; "unknown"
# outside git. OUT is rewritten only when its text changes. Stage products record it as
# `build_revision` (scripts/fiberform/_versions.py build_revision, docs/stages/pipeline.md); it is a
# file beside the binaries, not compiled into them, so a commit that changes no source leaves
# fiberdem byte-identical (its sha256 is a lay-down input).
execute_process(COMMAND git -C "${SRC}" rev-parse --short HEAD
                OUTPUT_VARIABLE rev RESULT_VARIABLE rc OUTPUT_STRIP_TRAILING_WHITESPACE ERROR_QUIET)
if(NOT rc EQUAL 0 OR rev STREQUAL "")
  set(text "unknown")
else()
  execute_process(COMMAND git -C "${SRC}" status --porcelain --untracked-files=no --
                          liggghts-fiber-style coupling cmake CMakeLists.txt
                  OUTPUT_VARIABLE changed RESULT_VARIABLE rc2 ERROR_QUIET)
  if(NOT rc2 EQUAL 0 OR NOT changed STREQUAL "")
    set(text "${rev}-dirty")
  else()
    set(text "${rev}")
  endif()
endif()
set(old "")
if(EXISTS "${OUT}")
  file(READ "${OUT}" old)
endif()
if(NOT old STREQUAL "${text}\n")
  file(WRITE "${OUT}" "${text}\n")
endif()
