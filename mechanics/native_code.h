// Derivative programs compiled to machine code at run time.
//
// A DerivativeProgram (mechanics/derivative_program.h) is interpreted: every operation
// stores its result in a slot and the next loads it, so a chain of dependent
// operations pays a store and a load on each link. On a small system that is most of a
// step (Kepler's force is 9 operations). Compiled, the program's values stay in
// registers (bench_written_lagrangian compares the two).
//
// compile_programs writes the programs as one C translation unit
// (DerivativeProgram::c_source), runs the machine's C compiler on it once, loads the
// shared object (dlopen) and returns copies of the programs that call its functions.
// The compiler is $DVM_CC when set (a command, flags allowed), else `cc`; it runs as
//   <compiler> -O2 -fPIC -shared -fno-math-errno -ffp-contract=off -fno-fast-math
//              -fno-builtin-pow -o <so> <c> -lm
// in a fresh directory under $TMPDIR (else /tmp), removed once the object is loaded.
// -ffp-contract=off keeps a*b + c two roundings (no fused multiply-add); -fno-fast-math
// undoes value-changing flags given with the compiler (and keeps gcc's crtfastmath.o,
// flush-to-zero for the whole process, out of the link); -fno-builtin-pow keeps
// pow(x, -1.0) and pow(x, 2.0) the libm calls the interpreter makes (gcc writes 1/x
// and x*x, which differ from glibc's pow in the last bit on some inputs);
// -fno-math-errno only stops libm setting errno. So compiled code gives the
// interpreter's results to the bit (tests/mechanics/test_derivative_program.cc). Code
// whose loading changes the floating-point control modes is refused.
// A run of the compiler costs tens of milliseconds, once per run (compile_seconds in
// the run report), and once per process for a given source and compiler: the process
// keeps the last 16 objects it loaded, and a later call for one of them binds its
// functions again (the rows of a sweep, the runs of a convergence study), its
// compile_seconds then the look-up's.
//
// Programs with blocks (sums over arrays) have no C source: their loops over the terms
// are interpreted already at array speed. compile_programs throws NativeCodeError
// naming what failed: a program it cannot write, the compiler's command, status and
// first lines of output, or the loader's message.
#pragma once

#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "mechanics/derivative_program.h"

namespace dvm {

struct NativeCodeError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// $DVM_CC when set and not empty, else "cc".
std::string default_c_compiler();

// The programs compiled, in order (each with its Hessian where it has one); one run of
// `compiler`. seconds (if given) receives the wall time, writing the source to loading
// the code. Throws NativeCodeError.
std::vector<std::shared_ptr<const DerivativeProgram>> compile_programs(const std::vector<const DerivativeProgram*>& programs,
                                                                       const std::string& compiler = default_c_compiler(),
                                                                       double* seconds = nullptr);

}  // namespace dvm
