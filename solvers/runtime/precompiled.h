// The headers of the runtime's kernel files (solvers/runtime/kernels_*.cc and
// check_map.cc), precompiled once per build when the compiler is clang
// (solvers/CMakeLists.txt says why clang only). Each kernel file still includes what
// it uses; this header only makes their common part a precompiled one.
#pragma once

#include "solvers/runtime/factories.h"
#include "solvers/runtime/kernels_dynamic.h"
#include "solvers/runtime/kernels_manifold.h"
#include "solvers/runtime/kernels_rn.h"
