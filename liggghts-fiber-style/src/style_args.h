/* SPDX-License-Identifier: GPL-3.0-or-later
   fiberform: helpers shared by the project's styles for argument checking and error messages. */
#ifndef FIBERFORM_STYLE_ARGS_H
#define FIBERFORM_STYLE_ARGS_H

#include <cstdio>
#include <string>

namespace LAMMPS_NS {
class Error;
class LAMMPS;
}

namespace fiberform {

// LIGGGHTS 3.8's Error::all() prints its message a second time after exit() has run static
// destructors, so a message held in a std::string (even a static one) comes out as garbage.
// This copies the message into plain static char storage (no destructor) and returns it; the
// next call overwrites it, which is fine because Error::all() does not return.
const char *error_text(const std::string &message);

// A finite number from an input-script word, or error->all() naming the style and keyword:
// "<style>: <keyword>: '<text>' is not a finite number".
double parse_finite(LAMMPS_NS::Error *error, const std::string &style, const std::string &keyword,
                    const char *text);

// A whole number in [lo, hi] from an input-script word, or error->all() naming the style and
// keyword: "<style>: <keyword>: '<text>' is not a whole number in [lo, hi]" (1.5 is refused, not
// truncated).
long long parse_count(LAMMPS_NS::Error *error, const std::string &style, const std::string &keyword,
                      const char *text, long long lo, long long hi);

// error->one() for a condition found on one rank only, with the message written and FLUSHED to the
// screen and log first: LIGGGHTS 3.8 calls MPI_Abort without flushing, so a message on a piped
// screen (a run started by Python) or in the log file is otherwise lost.
[[noreturn]] void fail_one(LAMMPS_NS::LAMMPS *lmp, const char *file, int line, const char *message);

// The whole content of an input file, read on rank 0 and broadcast to every rank (one reader, and a
// file that rank 0 cannot read ends every rank with error->all naming ``style`` and the path,
// instead of one rank failing while the others wait in the next collective call). Parse the
// returned bytes on every rank: a parse error is then found on all of them alike.
std::string read_file_everywhere(LAMMPS_NS::LAMMPS *lmp, const std::string &style, const std::string &path);

// A fix's global restart record (Fix::write_restart): n doubles, written by rank 0 behind their
// size in bytes, as LIGGGHTS reads them back into Fix::restart(buf).
void write_global_restart(LAMMPS_NS::LAMMPS *lmp, FILE *fp, const double *values, int n);

}  // namespace fiberform

#endif
