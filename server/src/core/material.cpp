#include "core/material.hpp"

namespace tactile {

std::string_view to_string(MaterialModel m) {
  switch (m) {
    case MaterialModel::Linear: return "linear";
    case MaterialModel::StVK: return "stvk";
    case MaterialModel::Corotational: return "corotational";
    case MaterialModel::NeoHookean: return "neohookean";
    case MaterialModel::InvertibleStVK: return "invertible_stvk";
  }
  return "?";
}

bool parse_material_model(std::string_view s, MaterialModel* out) {
  for (int i = 0; i < kMaterialModelCount; ++i) {
    const auto m = static_cast<MaterialModel>(i);
    if (s == to_string(m)) {
      *out = m;
      return true;
    }
  }
  return false;
}

}  // namespace tactile
