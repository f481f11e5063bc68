// The two sides of every element ("slots") and what each does with light: the one definition of
// the side rule of docs/guide/scenes.md, used by every method, the outputs and the bench.
//
// Slot 2e is element e's front (the counter-clockwise side of its polygon), slot 2e + 1 its back.
// For a material:
//  - the front exists always; the back exists when the material has a back side of its own
//    (two-sided, or transmitting): otherwise arriving light is absorbed there and nothing leaves;
//  - a side emits (exitance E = Ke) and reflects (R = Kd) on the front, and on the back only when
//    the material is two-sided;
//  - transmission works both ways: of the light arriving at a side, T leaves from the other side.
// So the power leaving a side, P = A E + R H + T H' (H: arriving at the side, H': at the other).
#ifndef RADIOSITY_SOLVER_GEOMETRY_SIDES_H_
#define RADIOSITY_SOLVER_GEOMETRY_SIDES_H_

#include <cstdint>
#include <string>
#include <vector>

#include "solver/geometry/scene.h"
#include "solver/geometry/vec.h"

namespace radiosity {

inline constexpr int kFront = 0;
inline constexpr int kBack = 1;

// Slot arithmetic: an element's sides are consecutive slots (patch sides, where a method keeps
// them, are numbered the same way: Slot(patch, side)).
inline int Slot(int element, int side) { return 2 * element + side; }
inline int ElementOfSlot(int slot) { return slot >> 1; }
inline int PatchOfSlot(int slot) { return slot >> 1; }
inline int SideOfSlot(int slot) { return slot & 1; }
inline int OtherSide(int slot) { return slot ^ 1; }

// What one side of a material does (see the file comment).
struct SideRule {
  bool exists = false;
  Rgb exitance;       // E: emitted radiant exitance, W/m^2 per channel.
  Rgb reflectance;    // R: the fraction of the light arriving here sent back out of this side.
  Rgb transmittance;  // T: the fraction of the light arriving here sent out of the other side.
  // S: the fraction of the light arriving here that leaves specularly (mirror + glossy + glass,
  // transport/specular.h), and its glass part.
  Rgb specular;
  Rgb glass;
  Rgb mirror;  // Its ideal mirror part.

  bool Emits() const { return exists && !exitance.IsZero(); }
  bool Reflects() const { return exists && !reflectance.IsZero(); }
  bool Transmits() const { return exists && !transmittance.IsZero(); }
  bool Specular() const { return exists && !specular.IsZero(); }
  // Does something diffuse with arriving light (reflects or passes it on).
  bool Receives() const { return Reflects() || Transmits(); }
  // Can send light out (B > 0): emits, reflects, or passes on what arrives at the other side
  // (a material's transmittance is the same on both sides).
  bool Sends() const { return Emits() || Reflects() || Transmits(); }
  std::string ToString() const;
};

// The rule of `side` (kFront or kBack) of a material.
SideRule MaterialSide(const Material& material, int side);

// The rules of every slot of a mesh's elements: per element only its material is stored, so the
// table costs 4 bytes per element.
class SideTable {
 public:
  SideTable() = default;
  // `element_surfaces[e]` is element e's surface (an index into scene.surfaces).
  SideTable(const Scene& scene, const std::vector<int32_t>& element_surfaces);

  const SideRule& operator[](int slot) const {
    return rules_[2 * static_cast<size_t>(material_[static_cast<size_t>(slot) >> 1]) + (slot & 1)];
  }
  const SideRule& at(int element, int side) const { return (*this)[Slot(element, side)]; }
  // The rule of a side of every element of surface `surface` (an index into Scene::surfaces).
  const SideRule& OfSurface(int surface, int side) const {
    return rules_[2 * static_cast<size_t>(surface_material_[static_cast<size_t>(surface)]) + side];
  }
  bool exists(int slot) const { return (*this)[slot].exists; }
  // 2 x elements.
  int64_t slots() const { return 2 * static_cast<int64_t>(material_.size()); }
  // Whether any element has a back side.
  bool any_back() const { return any_back_; }
  // Whether any element side has a specular part (mirror, glossy or glass).
  bool any_specular() const { return any_specular_; }

 private:
  std::vector<SideRule> rules_;            // 2 per material: front, back.
  std::vector<int32_t> material_;          // Per element.
  std::vector<int32_t> surface_material_;  // Per surface.
  bool any_back_ = false;
  bool any_specular_ = false;
};

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_GEOMETRY_SIDES_H_
