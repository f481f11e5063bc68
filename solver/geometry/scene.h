// The scene model every loader produces and every solver consumes: named surfaces made of planar
// (or nearly planar) polygons, each surface with one diffuse material.
//
// Conventions (docs/guide/scenes.md):
//  - A polygon's front is its counter-clockwise side (right-hand rule about the vertex order).
//  - A surface reflects and emits from its front only, unless its material is two-sided; every
//    polygon blocks light from both sides.
//  - `emission` is radiant exitance in W/m^2 per channel (a surface emits emission x area), in
//    whatever length unit the coordinates use; radiosity is reported in the same units.
#ifndef RADIOSITY_SOLVER_GEOMETRY_SCENE_H_
#define RADIOSITY_SOLVER_GEOMETRY_SCENE_H_

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "solver/geometry/vec.h"

namespace radiosity {

// What loaders give faces without a usable material (no usemtl, an unknown name, a missing
// library): a neutral grey, diffuse reflectance 0.5.
inline constexpr char kDefaultMaterialName[] = "default_grey";
inline constexpr double kDefaultReflectance = 0.5;
// Reflectances read at or above 1 are clamped to this: a closed model of reflectance 1 would never
// converge, and 0.99 is as white as real paint gets.
inline constexpr double kMaxReflectance = 0.99;

// Bounds of a material's glossy exponent and index of refraction.
inline constexpr double kMaxGlossyExponent = 1e6;
inline constexpr double kMaxIor = 10;
// Importers make a glossy lobe sharper than this exponent an ideal mirror.
inline constexpr double kMirrorExponent = 1e4;

struct Material {
  std::string name;
  Rgb reflectance;    // Kd: diffuse reflectance per channel, in [0, 1).
  Rgb emission;       // Ke: emitted radiant exitance, W/m^2 per channel, >= 0.
  Rgb transmittance;  // Tf: diffuse transmittance; reflectance + transmittance <= 1.
  bool two_sided = false;
  int line = 0;  // Line of the definition in its source file (0 when not from a text file).
  // Specular parts (docs/guide/specular.md), fractions of the arriving light per
  // channel; reflectance + transmittance + mirror + glossy + glass <= 1 per channel.
  Rgb mirror;  // Ideal specular reflection.
  Rgb glossy;  // Reflection into a glossy lobe about the mirror direction (glossy.h).
  double glossy_exponent = 0;  // The lobe's Phong exponent (>= 1 when glossy is non-zero).
  // Meets a clear dielectric of index `ior`: Fresnel's fraction is reflected as by a mirror, the
  // rest passes straight through a thin sheet (refracts = false) or is refracted into the back
  // side's medium (refracts = true: the front faces the air).
  Rgb glass;
  double ior = 1.5;
  bool refracts = false;
  // Read from MTL (Ks, Ns, illum) as written; the specular parts above are derived from them.
  Rgb specular;
  double shininess = 0;
  int illum = -1;  // -1: not given.

  bool IsEmitter() const { return emission.Sum() > 0; }
  bool Transmits() const { return transmittance.Sum() > 0; }
  // Whether some arriving light leaves specularly (mirror, glossy or glass).
  bool IsSpecular() const { return mirror.Sum() + glossy.Sum() + glass.Sum() > 0; }
  // Whether the surface has a back side of its own (reflects or emits from both sides).
  bool HasBackSide() const { return two_sided || Transmits() || !glass.IsZero(); }
  std::string ToString() const;
};

struct Surface {
  std::string name;
  int material = -1;  // Index into Scene::materials.
  int line = 0;       // Line where the surface starts in its source file, 0 if none.
  std::string ToString() const;
};

struct Face {
  int surface = -1;  // Index into Scene::surfaces.
  std::vector<int>
      vertices;  // Indices into Scene::vertices, counter-clockwise seen from the front.
  int line = 0;  // Line in the source file, 0 if none.
};

struct Scene {
  std::string source;  // File the scene came from (for messages); may be empty.
  std::vector<Vec3> vertices;
  std::vector<Material> materials;
  std::vector<Surface> surfaces;
  std::vector<Face> faces;

  // "file:line: " when the line is known, else "file: " (or "" when there is no file).
  std::string Where(int line) const;
  // A human description of face `f`: surface name, face index within the surface, line.
  std::string DescribeFace(int f) const;
  std::string ToString() const;
};

// A point where irradiance is wanted (a sensor): position in scene coordinates and unit normal.
struct SensorPoint {
  Vec3 p;
  Vec3 n;
  std::string grid;  // The named grid it belongs to (empty: none).
};

// A surface's thermal data for radiative exchange (solver/methods/exchange.h). The surface "*"
// stands for every surface not named otherwise.
struct SurfaceThermal {
  std::string surface;
  double emissivity = 1;   // Hemispherical total emissivity, in [0, 1].
  double temperature = 0;  // Kelvin, >= 0.
};

// Checks the rules of docs/guide/scenes.md: finite coordinates, indices in range, at least 3
// vertices per face and at most kMaxFaceVertices, reflectance in [0, 1), reflectance +
// transmittance <= 1 per channel, emission
// >= 0 and finite, every surface has a material, at least one face. Messages name the file, line or
// surface and the problem.
inline constexpr size_t kMaxFaceVertices = 4096;
absl::Status ValidateScene(const Scene& scene);

// Checks a material's specular parts: mirror, glossy and glass each in [0, 1], reflectance +
// transmittance + mirror + glossy + glass <= 1 per channel, a glossy exponent in [1,
// kMaxGlossyExponent] where glossy is non-zero, an index of refraction in [1, kMaxIor] where glass
// is. `where` prefixes the message.
absl::Status ValidateSpecularParts(const Material& m, const std::string& where);

// Removes faces whose area is zero (or below 1e-15 of the scene's largest face) and appends a
// warning for each to `warnings` (for the first kMaxDroppedFaceWarnings, then one line counting
// the rest). Linear in the number of faces. Call after ValidateScene. Fails if no face is left.
inline constexpr int64_t kMaxDroppedFaceWarnings = 100;
absl::Status DropDegenerateFaces(Scene* scene, std::vector<std::string>* warnings);

// Area of a polygon given by its vertices (half the norm of the vector area), exact for planar
// ones.
double PolygonArea(const Scene& scene, const Face& face);

// Total emitted power per channel (emission x area of the front, and of the back if two-sided).
Rgb EmittedPower(const Scene& scene);

// What a solve of a scene without an emitter is told (after the scene's name).
inline constexpr char kNoEmitterMessage[] =
    "the scene has no emitter (no material with emission Ke > 0): there is no light to solve for; "
    "make a material or surface emit with --emit NAME=R,G,B (SolveSpec.emit), or light it from "
    "outside with --sky uniform=E or --sky overcast=E (SolveSpec.sky), or place luminaires with "
    "--luminaire 'FILE.ies at=X,Y,Z' (SolveSpec.luminaires) (view factors need no emitter)";

// Light for a model that carries none (`--emit NAME=R,G,B`, SolveSpec.emit): `name` is a material
// or a surface, `exitance` its radiant exitance in W/m^2 per channel (as MTL's Ke).
struct EmitOverride {
  std::string name;
  Rgb exitance;
  std::string ToString() const;
};

// Applies `emit` in order: a material named `name` emits `exitance` (every surface of it);
// otherwise every surface named `name` gets a copy of its material, named "MATERIAL@SURFACE",
// that does. INVALID_ARGUMENT naming `name` and the names the scene has when neither exists, or
// when an exitance is negative or not finite.
absl::Status ApplyEmitOverrides(const std::vector<EmitOverride>& emit, Scene* scene);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_GEOMETRY_SCENE_H_
