#include "render/obj_writer.h"

#include <cstdio>
#include <filesystem>
#include <string>

#include "util/atomic_file.h"
#include "util/error.h"
#include "util/image_io.h"

namespace paircast {
namespace fs = std::filesystem;

namespace {

void appendf(std::string& out, const char* fmt, double a, double b, double c) {
  char buf[128];
  std::snprintf(buf, sizeof buf, fmt, a, b, c);
  out += buf;
}

std::string textureName(const Mesh& mesh, int t, const std::string& format) {
  std::string name =
      mesh.textures[t].name.empty() ? "texture" + std::to_string(t) : mesh.textures[t].name;
  for (auto& c : name)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '_' && c != '-') c = '_';
  return name + "." + format;
}

}  // namespace

void writeObj(const std::string& path, const Mesh& mesh, const std::string& textureFormat) {
  mesh.validate(path);
  const fs::path p(path);
  const std::string stem = p.stem().string();
  const fs::path dir = p.parent_path().empty() ? fs::path(".") : p.parent_path();
  makeDirs(dir.string());
  if (!mesh.textures.empty()) makeDirs((dir / "textures").string());
  for (size_t t = 0; t < mesh.textures.size(); ++t) {
    const Texture& tex = mesh.textures[t];
    Image8 img(tex.width, tex.height, 3);
    for (size_t i = 0; i < static_cast<size_t>(tex.width) * tex.height; ++i)
      for (int c = 0; c < 3; ++c) img.data[3 * i + c] = tex.texels[i * tex.channels + c];
    writeImage((dir / "textures" / textureName(mesh, static_cast<int>(t), textureFormat)).string(),
               img);
  }

  std::string mtl = "# written by paircast\n";
  for (size_t m = 0; m < mesh.materials.size(); ++m) {
    const Material& mat = mesh.materials[m];
    mtl += "newmtl m" + std::to_string(m) + "\n";
    appendf(mtl, "Kd %.6f %.6f %.6f\n", mat.baseColor.x(), mat.baseColor.y(), mat.baseColor.z());
    if (mat.texture >= 0)
      mtl += "map_Kd textures/" + textureName(mesh, mat.texture, textureFormat) + "\n";
  }
  writeFileAtomic((dir / (stem + ".mtl")).string(), mtl);

  std::string obj = "# written by paircast\nmtllib " + stem + ".mtl\n";
  obj.reserve(mesh.numVertices() * 64 + mesh.numTriangles() * 40);
  for (const auto& v : mesh.positions) appendf(obj, "v %.6f %.6f %.6f\n", v.x(), v.y(), v.z());
  for (const auto& t : mesh.uvs) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "vt %.6f %.6f\n", t.x(), t.y());
    obj += buf;
  }
  int current = -1;
  for (size_t t = 0; t < mesh.numTriangles(); ++t) {
    if (mesh.triangleMaterial[t] != current) {
      current = mesh.triangleMaterial[t];
      obj += "usemtl m" + std::to_string(current) + "\n";
    }
    const Eigen::Vector3i& f = mesh.triangles[t];
    char buf[96];
    std::snprintf(buf, sizeof buf, "f %d/%d %d/%d %d/%d\n", f[0] + 1, f[0] + 1, f[1] + 1, f[1] + 1,
                  f[2] + 1, f[2] + 1);
    obj += buf;
  }
  writeFileAtomic(path, obj);
}

}  // namespace paircast
