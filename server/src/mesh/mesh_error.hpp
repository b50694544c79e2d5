// The one error type of the mesh library: bad input files, bad surfaces,
// meshes refused by the quality check. The message names the file, line,
// field or element at fault, so it can be shown to the user as is.
#pragma once

#include <stdexcept>

namespace tactile {

struct MeshError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

}  // namespace tactile
