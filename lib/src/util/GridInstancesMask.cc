// SPDX-License-Identifier: Apache-2.0
// The one compiled copy of OpenVDB's mask grid and tree classes that ExternGrids.h declares
// extern everywhere else (three files, so that two cores compile them side by side).
#include "ExternGrids.h"

#define IVDB_GRID_INSTANCE(TreeT)           \
    template class openvdb::Grid<TreeT>; \
    template class openvdb::tree::Tree<TreeT::RootNodeType>;
IVDB_MASK_TREES(IVDB_GRID_INSTANCE)
