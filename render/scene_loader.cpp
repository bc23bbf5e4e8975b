#include "render/scene_loader.h"

#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <assimp/DefaultLogger.hpp>
#include <assimp/Importer.hpp>

#include <filesystem>
#include <map>

#include "util/error.h"
#include "util/image_io.h"

namespace paircast {
namespace fs = std::filesystem;

UpAxis parseUpAxis(const std::string& text) {
  if (text == "y" || text == "Y") return UpAxis::Y;
  if (text == "z" || text == "Z") return UpAxis::Z;
  throw Error("invalid up axis '" + text + "' (use y or z)");
}

Eigen::Vector3f upVector(UpAxis up) {
  return up == UpAxis::Y ? Eigen::Vector3f::UnitY() : Eigen::Vector3f::UnitZ();
}

bool isSupportedSceneFile(const std::string& path) {
  Assimp::Importer importer;
  std::string ext = fs::path(path).extension().string();
  return !ext.empty() && importer.IsExtensionSupported(ext);
}

namespace {

std::string lower(std::string s) {
  for (auto& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// Converts one assimp material and its texture to ours, loading each texture file once.
class MaterialBuilder {
 public:
  MaterialBuilder(const aiScene* scene, const std::string& path, Mesh& mesh,
                  std::vector<std::string>& warnings)
      : scene_(scene),
        path_(path),
        dir_(fs::path(path).parent_path()),
        mesh_(mesh),
        warnings_(warnings) {}

  int build(const aiMaterial* in) {
    Material m;
    aiString name;
    if (in->Get(AI_MATKEY_NAME, name) == AI_SUCCESS) m.name = name.C_Str();
    aiColor4D color;
    if (in->Get(AI_MATKEY_BASE_COLOR, color) == AI_SUCCESS ||
        in->Get(AI_MATKEY_COLOR_DIFFUSE, color) == AI_SUCCESS) {
      m.baseColor = Eigen::Vector3f(color.r, color.g, color.b).cwiseMax(0.0f).cwiseMin(1.0f);
    }
    aiString texPath;
    if (in->GetTexture(aiTextureType_BASE_COLOR, 0, &texPath) == AI_SUCCESS ||
        in->GetTexture(aiTextureType_DIFFUSE, 0, &texPath) == AI_SUCCESS) {
      m.texture = texture(texPath.C_Str());
      // A texture is modulated by the factor; OBJ files often set Kd to 0 with a map_Kd.
      if (m.texture >= 0 && m.baseColor.maxCoeff() <= 0.0f) m.baseColor.setOnes();
    }
    return mesh_.addMaterial(m);
  }

 private:
  int texture(const std::string& ref) {
    auto it = cache_.find(ref);
    if (it != cache_.end()) return it->second;
    int index = -1;
    try {
      Texture t;
      t.name = ref;
      Image8 img;
      if (const aiTexture* emb = scene_->GetEmbeddedTexture(ref.c_str())) {
        if (emb->mHeight == 0) {  // compressed (png/jpg) bytes
          img =
              decodeImage8(emb->pcData, emb->mWidth, path_ + ":" + ref + "." + emb->achFormatHint);
        } else {  // raw BGRA texels
          img = Image8(emb->mWidth, emb->mHeight, 3);
          for (size_t i = 0; i < size_t(emb->mWidth) * emb->mHeight; ++i) {
            img.data[3 * i] = emb->pcData[i].r;
            img.data[3 * i + 1] = emb->pcData[i].g;
            img.data[3 * i + 2] = emb->pcData[i].b;
          }
        }
      } else {
        std::string rel = ref;
        for (auto& c : rel)
          if (c == '\\') c = '/';
        img = readImage8((dir_ / rel).string());
      }
      t.width = img.width;
      t.height = img.height;
      t.channels = 3;
      t.texels = std::move(img.data);
      mesh_.textures.push_back(std::move(t));
      index = static_cast<int>(mesh_.textures.size()) - 1;
    } catch (const Error& e) {
      // A missing texture should not lose the scene: fall back to the colour factor.
      warnings_.push_back(std::string("texture skipped: ") + e.what());
    }
    cache_[ref] = index;
    return index;
  }

  const aiScene* scene_;
  std::string path_;
  fs::path dir_;
  Mesh& mesh_;
  std::vector<std::string>& warnings_;
  std::map<std::string, int> cache_;
};

void appendNode(const aiScene* scene, const aiNode* node, const aiMatrix4x4& parent,
                const std::vector<int>& materialMap, bool linearVertexColors, float scale,
                Mesh& out) {
  const aiMatrix4x4 world = parent * node->mTransformation;
  for (unsigned k = 0; k < node->mNumMeshes; ++k) {
    const aiMesh* m = scene->mMeshes[node->mMeshes[k]];
    if (!(m->mPrimitiveTypes & aiPrimitiveType_TRIANGLE)) continue;
    const int base = static_cast<int>(out.positions.size());
    for (unsigned i = 0; i < m->mNumVertices; ++i) {
      aiVector3D p = world * m->mVertices[i];
      out.positions.emplace_back(p.x * scale, p.y * scale, p.z * scale);
      if (m->HasTextureCoords(0))
        out.uvs.emplace_back(m->mTextureCoords[0][i].x, m->mTextureCoords[0][i].y);
      else
        out.uvs.emplace_back(0.0f, 0.0f);
      if (m->HasVertexColors(0)) {
        const aiColor4D& c = m->mColors[0][i];
        Eigen::Vector3f rgb = Eigen::Vector3f(c.r, c.g, c.b).cwiseMax(0.0f).cwiseMin(1.0f);
        if (!linearVertexColors)
          rgb =
              Eigen::Vector3f(srgbToLinear(rgb.x()), srgbToLinear(rgb.y()), srgbToLinear(rgb.z()));
        out.colors.push_back(rgb);
      } else {
        out.colors.emplace_back(1.0f, 1.0f, 1.0f);
      }
    }
    const int material = materialMap.at(m->mMaterialIndex);
    for (unsigned f = 0; f < m->mNumFaces; ++f) {
      const aiFace& face = m->mFaces[f];
      if (face.mNumIndices != 3) continue;  // points and lines left by SortByPType
      out.triangles.emplace_back(base + face.mIndices[0], base + face.mIndices[1],
                                 base + face.mIndices[2]);
      out.triangleMaterial.push_back(material);
    }
  }
  for (unsigned c = 0; c < node->mNumChildren; ++c)
    appendNode(scene, node->mChildren[c], world, materialMap, linearVertexColors, scale, out);
}

}  // namespace

Scene loadScene(const std::string& path, const LoadOptions& options) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw Error(path, "no such file");
  if (fs::is_directory(path, ec)) throw Error(path, "is a folder, not a scene file");
  const uint64_t bytes = fs::file_size(path, ec);
  if (ec) throw Error(path, "cannot read file size: " + ec.message());
  if (bytes == 0) throw Error(path, "file is empty");
  if (bytes > options.maxFileBytes)
    throw Error(path, "file is larger than the limit (" + std::to_string(bytes) + " bytes)");
  if (!(options.scale > 0) || !std::isfinite(options.scale))
    throw Error(path, "scale must be a positive number");
  if (!isSupportedSceneFile(path))
    throw Error(path, "unsupported scene format '" + fs::path(path).extension().string() +
                          "' (glb, gltf, obj, ply, fbx, dae, ifc, ... are supported)");

  Assimp::Importer importer;
  const unsigned flags =
      aiProcess_Triangulate | aiProcess_SortByPType | aiProcess_ValidateDataStructure;
  importer.SetPropertyInteger(AI_CONFIG_PP_SBP_REMOVE,
                              aiPrimitiveType_POINT | aiPrimitiveType_LINE);
  const aiScene* scene = nullptr;
  try {
    scene = importer.ReadFile(path, flags);
  } catch (const std::exception& e) {
    throw Error(path, std::string("cannot load scene: ") + e.what());
  }
  if (!scene) throw Error(path, std::string("cannot load scene: ") + importer.GetErrorString());
  if (!scene->mRootNode || (scene->mFlags & AI_SCENE_FLAGS_INCOMPLETE))
    throw Error(path, "scene is incomplete or has no geometry");

  size_t triangles = 0, vertices = 0;
  for (unsigned i = 0; i < scene->mNumMeshes; ++i) {
    triangles += scene->mMeshes[i]->mNumFaces;
    vertices += scene->mMeshes[i]->mNumVertices;
  }
  if (triangles > options.maxTriangles)
    throw Error(path, "scene has " + std::to_string(triangles) + " faces, more than the limit of " +
                          std::to_string(options.maxTriangles));

  Scene out;
  out.path = path;
  out.name = fs::path(path).stem().string();
  out.up = options.up;
  out.mesh.positions.reserve(vertices);
  out.mesh.triangles.reserve(triangles);

  MaterialBuilder materials(scene, path, out.mesh, out.warnings);
  std::vector<int> materialMap;
  for (unsigned i = 0; i < scene->mNumMaterials; ++i)
    materialMap.push_back(materials.build(scene->mMaterials[i]));
  if (materialMap.empty()) materialMap.push_back(out.mesh.addMaterial(Material{}));

  const std::string ext = lower(fs::path(path).extension().string());
  const bool linearVertexColors = ext == ".glb" || ext == ".gltf";
  appendNode(scene, scene->mRootNode, aiMatrix4x4(), materialMap, linearVertexColors,
             static_cast<float>(options.scale), out.mesh);
  // A mesh referenced by several nodes is instanced once per node: enforce the limit again.
  if (out.mesh.numTriangles() > options.maxTriangles)
    throw Error(path, "scene has more triangles than the limit after instancing");
  if (out.mesh.numTriangles() == 0) throw Error(path, "scene has no triangles");
  out.mesh.validate(path);
  return out;
}

}  // namespace paircast
