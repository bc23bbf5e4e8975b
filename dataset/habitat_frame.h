// Habitat's conventions, for CroCo's metadata.json files (docs/conventions.md, "Habitat"):
//   - a camera orientation is a quaternion (w, x, y, z) of habitat's camera axes (x right, y up,
//     z back) in habitat's world: R_cam2world = R(q) * diag(1, -1, -1) in OpenCV camera axes;
//   - habitat's world is y-up with -z in front. A stage loaded from a .glb without a config (HM3D,
//     MP3D, Gibson, the habitat test scenes) is taken as z-up with +y in front, and rotated into
//     that world: habitat = (x, z, -y) of the file's coordinates. y-up stages are not rotated.
// paircast keeps scenes in their file's frame, so poses from CroCo's metadata are mapped back
// into it (sceneFromHabitat); paircast's own metadata is written in the file's frame already.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>

#include "render/scene_loader.h"

namespace paircast {

using HabitatQuaternion = std::array<double, 4>;  // w, x, y, z

// The quaternion of a camera rotation (OpenCV axes, R_cam2world).
HabitatQuaternion habitatQuaternion(const Eigen::Matrix3d& R_cam2world);
// R_cam2world (OpenCV axes) of a quaternion; normalises it. Throws paircast::Error on a zero or
// non-finite quaternion.
Eigen::Matrix3d cameraRotationFromHabitat(const HabitatQuaternion& q);

// sceneFromHabitat: maps habitat world coordinates into the scene file's frame, for a scene whose
// up axis is `up` (identity for y, the inverse of (x, y, z) -> (x, z, -y) for z).
Eigen::Matrix3d sceneFromHabitat(UpAxis up);

}  // namespace paircast
