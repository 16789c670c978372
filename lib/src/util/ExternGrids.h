// SPDX-License-Identifier: Apache-2.0
// Force-included into every file that ivdb's build compiles (the top-level CMakeLists.txt,
// ivdb_compile_fast): OpenVDB's grid and tree classes, compiled once.
//
// OpenVDB 10 declares its tools' common instantiations extern, but not Grid<T> and Tree<T>
// themselves. Every file that creates a grid of a type therefore compiles that type's whole
// virtual interface (reading, writing, copying, merging, printing) at -O3 again, and the linker
// keeps one copy: a test that makes grids of nine types took 95 s of clang for 111 lines. Declared
// extern here, each class is compiled once, in GridInstances*.cc of the library; inline members
// stay inlinable everywhere. Not part of the installed headers: a program linking libivdb
// compiles what it uses, as before.
#pragma once

#include <openvdb/openvdb.h>

/// The tree types whose grids are compiled once, grouped as GridInstances*.cc compiles them.
#define IVDB_SCALAR_TREES(X) X(openvdb::FloatTree) X(openvdb::DoubleTree) \
    X(openvdb::Int32Tree) X(openvdb::Int64Tree)
#define IVDB_VECTOR_TREES(X) X(openvdb::Vec3STree) X(openvdb::Vec3DTree) X(openvdb::Vec3ITree)
#define IVDB_MASK_TREES(X) X(openvdb::BoolTree) X(openvdb::MaskTree)

#define IVDB_EXTERN_GRID(TreeT)                    \
    extern template class openvdb::Grid<TreeT>; \
    extern template class openvdb::tree::Tree<TreeT::RootNodeType>;
IVDB_SCALAR_TREES(IVDB_EXTERN_GRID)
IVDB_VECTOR_TREES(IVDB_EXTERN_GRID)
IVDB_MASK_TREES(IVDB_EXTERN_GRID)
#undef IVDB_EXTERN_GRID
