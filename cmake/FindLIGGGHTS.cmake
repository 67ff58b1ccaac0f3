# SPDX-License-Identifier: GPL-3.0-or-later
# Find Debian's packaged LIGGGHTS (libliggghts-dev). Debian ships no CMake or pkg-config file,
# so we look for the header and the library ourselves and create the imported target LIGGGHTS::liggghts.
find_path(LIGGGHTS_INCLUDE_DIR NAMES lammps.h pair_gran.h PATH_SUFFIXES liggghts
          PATHS /usr/include /usr/local/include)
find_library(LIGGGHTS_LIBRARY NAMES liggghts)
include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(LIGGGHTS REQUIRED_VARS LIGGGHTS_LIBRARY LIGGGHTS_INCLUDE_DIR)
if(LIGGGHTS_FOUND AND NOT TARGET LIGGGHTS::liggghts)
  add_library(LIGGGHTS::liggghts SHARED IMPORTED)
  set_target_properties(LIGGGHTS::liggghts PROPERTIES
    IMPORTED_LOCATION "${LIGGGHTS_LIBRARY}"
    INTERFACE_INCLUDE_DIRECTORIES "${LIGGGHTS_INCLUDE_DIR}"
    # Debian's library uses the lmptype.h default (LAMMPS_SMALLBIG). Never define
    # SUPERQUADRIC_ACTIVE_FLAG / NONSPHERICAL_ACTIVE_FLAG: they change struct layouts.
    INTERFACE_COMPILE_DEFINITIONS "LAMMPS_SMALLBIG")
endif()
mark_as_advanced(LIGGGHTS_INCLUDE_DIR LIGGGHTS_LIBRARY)
