// `dvm run` for the integrator forms, the chain and boundary-value problems of issue 3
// (see run_forms.cc). Called from run_scene in run.cc; they throw InputError for bad
// input and return the exit status otherwise.
#pragma once

#include "examples/dvm/commands.h"

namespace dvm::cli {

int run_form(const Scene& scene, const RunOptions& options);            // form != "lagrangian"
int run_chain(const Scene& scene, const RunOptions& options);           // system = "chain"
int run_boundary_value(const Scene& scene, const RunOptions& options);  // kind = "boundary-value"

}  // namespace dvm::cli
