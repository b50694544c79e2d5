// Replacement for TetGen's error exit, terminatetetgen(), in library mode.
//
// Debian's TetGen 1.5.0 frees the mesh in terminatetetgen() and then throws,
// and the mesh's destructor frees it again while the exception unwinds: every
// TetGen error became a double free (a crash). libtet.so calls
// terminatetetgen() through the PLT, so this definition, exported by the
// executable that links it, takes its place: it only throws the code, and the
// destructor frees the mesh once. (Some scratch arrays of the failed run
// leak, ~100 KB per failure.) tetgen_test.cpp's self-intersection test
// exercises this path.
//
// This file must not include tetgen.h, whose inline definition this replaces.

class tetgenmesh;

void terminatetetgen(tetgenmesh* /*mesh*/, int code);
void terminatetetgen(tetgenmesh* /*mesh*/, int code) { throw code; }

namespace tactile {
// Read by tetgen.cpp, so that linking tetrahedralize() from the static
// library also links this file (nothing else refers to it: libtet.so has its
// own, weak, terminatetetgen).
extern const bool kTetgenTerminateReplaced;
const bool kTetgenTerminateReplaced = true;
}  // namespace tactile
