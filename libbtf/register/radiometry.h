#pragma once
// Radiometry: photo pixel values -> BRDF in 1/sr, WITHOUT cos(theta_i) (the dataset convention).
//
// The manifest's model (libbtf/io/rig.h): pixel = exposure * L, L = f * E, so
//   f(x) = pixel(x) / (exposure * E(x)),
// with the irradiance E at plate point x = (x, y, 0) (mm):
//   directional light (light_distance_mm = 0):  E = I * cos(theta_l)         (I = light_intensity)
//   point light at s = light_distance_mm * light_dir:
//                                      E(x) = I * max(0, (s - x).z) / |s - x|^3
//                                           = I * cos(theta_i(x)) / r(x)^2  (r in mm)
// i.e. the 1/r^2 fall-off and the cos(theta_i) of the light direction as seen from each texel.
// No cos(theta_v) term: the camera measures radiance.
#include "libbtf/io/image_io.h"
#include "libbtf/io/rig.h"

namespace btf {

// Irradiance at plate point (x, y, 0) mm; <= 0 if the light is at or below that point's horizon.
double IrradianceAt(const PhotoEntry& photo, const Vec2& plate_mm);

// Divides the normtexture (N x N over a sample of side sample_size_mm, see rectify.h) in place.
// Throws btf::Error (bad input) naming the photo if the light is below the horizon of any texel.
void ApplyRadiometry(Image& normtexture, const PhotoEntry& photo, double sample_size_mm);

}  // namespace btf
