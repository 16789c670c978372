# SPDX-License-Identifier: Apache-2.0
# OpenVDB installs FindOpenVDB.cmake (and Find modules for its dependencies) in
# <libdir>/cmake/OpenVDB rather than a package config: find that folder and put it on
# CMAKE_MODULE_PATH, so that find_package(OpenVDB) gives OpenVDB::openvdb. Used by ivdb's build
# and by its installed package (ivdbConfig.cmake).
find_path(IVDB_OPENVDB_MODULE_DIR FindOpenVDB.cmake
  PATH_SUFFIXES lib/${CMAKE_LIBRARY_ARCHITECTURE}/cmake/OpenVDB lib/cmake/OpenVDB
                lib64/cmake/OpenVDB cmake/OpenVDB
  DOC "Folder of OpenVDB's FindOpenVDB.cmake")
if(NOT IVDB_OPENVDB_MODULE_DIR)
  message(FATAL_ERROR "FindOpenVDB.cmake not found: install OpenVDB (Debian: libopenvdb-dev), "
                      "or set IVDB_OPENVDB_MODULE_DIR to the folder that holds it")
endif()
list(APPEND CMAKE_MODULE_PATH ${IVDB_OPENVDB_MODULE_DIR})
