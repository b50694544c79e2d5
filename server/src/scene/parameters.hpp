// The parameters a controller may change in a running scene, by name:
//
//   material.E | material.nu | material.rho      every material [Pa, -, kg/m^3]
//   materials[i].E | .nu | .rho                  material of region i
//   bodies[b].material.E | .nu | .rho            every material of body b (a scene of several bodies)
//   bodies[b].materials[i].E | .nu | .rho        material of body b's region i
//   damping.alpha                                Rayleigh mass damping [1/s], eq. (10); 0 turns damping off
//   gravity.x | gravity.y | gravity.z            [m/s^2]; all zero turns gravity off
//   friction.mu                                  every proxy's Coulomb coefficient; 0 on all turns friction off
//   proxies[i].friction                          one proxy's
//   effects.gravity | effects.damping | effects.friction   1 on, 0 off
//
// A change is applied to the spec, which the caller rebuilds the model from
// (the live server carries the body's state over: sim/simulation.hpp).
// Setting a value that needs an effect turns the effect on, so that a scene
// only pays for the effects it uses: alpha > 0 turns damping on, alpha = 0
// off. Values out of range are refused with a message naming the parameter
// and the range; so is a name this list lacks.
#pragma once

#include <string>
#include <vector>

#include "core/spec.hpp"

namespace tactile {

struct Parameter {
  std::string name;
  double value = 0;
  double min = 0, max = 0;  // allowed range, inclusive unless noted in `unit`
  std::string unit;
};

// The parameters of this spec with their current values, in a stable order
// (per-material entries only when there is more than one material, named by
// body in a scene of several; friction only when there are proxies).
std::vector<Parameter> list_parameters(const ModelSpec& spec);

// Sets one parameter; throws SceneError (scene/scene.hpp) naming what is wrong.
void apply_parameter(ModelSpec& spec, const std::string& name, double value);

}  // namespace tactile
