/* SPDX-License-Identifier: GPL-3.0-or-later */
#include "style_args.h"

#include <mpi.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <sstream>

#include "comm.h"
#include "error.h"
#include "lammps.h"

namespace fiberform {

const char *error_text(const std::string &message) {
  static char buffer[1024];
  std::snprintf(buffer, sizeof buffer, "%s", message.c_str());
  return buffer;
}

double parse_finite(LAMMPS_NS::Error *error, const std::string &style, const std::string &keyword,
                    const char *text) {
  char *end = nullptr;
  const double v = std::strtod(text, &end);
  if (end == text || *end != '\0' || !std::isfinite(v))
    error->all(FLERR, error_text(style + ": " + keyword + ": '" + text + "' is not a finite number"));
  return v;
}

long long parse_count(LAMMPS_NS::Error *error, const std::string &style, const std::string &keyword,
                      const char *text, long long lo, long long hi) {
  char *end = nullptr;
  const double v = std::strtod(text, &end);
  if (end == text || *end != '\0' || !std::isfinite(v) || v != std::floor(v) || v < static_cast<double>(lo) ||
      v > static_cast<double>(hi))
    error->all(FLERR, error_text(style + ": " + keyword + ": '" + text + "' is not a whole number in [" +
                                 std::to_string(lo) + ", " + std::to_string(hi) + "]"));
  return static_cast<long long>(v);
}

void fail_one(LAMMPS_NS::LAMMPS *lmp, const char *file, int line, const char *message) {
  const char *text = error_text(message);
  if (lmp->screen) {
    std::fprintf(lmp->screen, "ERROR on proc %d: %s\n", lmp->comm->me, text);
    std::fflush(lmp->screen);
  }
  if (lmp->logfile) {
    std::fprintf(lmp->logfile, "ERROR on proc %d: %s\n", lmp->comm->me, text);
    std::fflush(lmp->logfile);
  }
  lmp->error->one(file, line, text);
  std::abort();  // not reached: Error::one aborts
}

std::string read_file_everywhere(LAMMPS_NS::LAMMPS *lmp, const std::string &style, const std::string &path) {
  MPI_Comm world = lmp->world;
  std::string content, why;
  long long size = 0;
  if (lmp->comm->me == 0) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream all;
    if (!in || !(all << in.rdbuf())) {
      why = "cannot read " + path;
      size = -1;
    } else {
      content = all.str();
      size = static_cast<long long>(content.size());
      if (size > std::numeric_limits<int>::max()) {
        why = path + ": larger than 2 GiB (one broadcast)";
        size = -1;
      }
    }
  }
  MPI_Bcast(&size, 1, MPI_LONG_LONG, 0, world);
  if (size < 0) lmp->error->all(FLERR, error_text(style + ": " + why));  // printed by rank 0, which knows why
  content.resize(static_cast<std::size_t>(size));
  if (size > 0) MPI_Bcast(content.data(), static_cast<int>(size), MPI_CHAR, 0, world);
  return content;
}

void write_global_restart(LAMMPS_NS::LAMMPS *lmp, FILE *fp, const double *values, int n) {
  if (lmp->comm->me != 0) return;
  const int size = n * static_cast<int>(sizeof(double));
  std::fwrite(&size, sizeof(int), 1, fp);
  std::fwrite(values, sizeof(double), static_cast<size_t>(n), fp);
}

}  // namespace fiberform
