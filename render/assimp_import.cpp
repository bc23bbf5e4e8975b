#include "render/assimp_import.h"

#include <assimp/DefaultIOSystem.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <assimp/Importer.hpp>

#include <cstring>
#include <filesystem>
#include <map>

#include "util/error.h"
#include "util/image_io.h"

namespace paircast {
namespace {
namespace fs = std::filesystem;

// ---- what assimp may open ----

// Why a file a scene names may not be opened, or "" when it may: only regular files (a scene
// naming /dev/zero or a FIFO must not hang or fill memory) within the size limit.
std::string refusalOf(const std::string& file, uint64_t maxBytes) {
  std::error_code ec;
  const fs::file_status st = fs::status(file, ec);  // follows symlinks: the target counts
  if (ec || !fs::exists(st)) return "no such file";
  if (!fs::is_regular_file(st)) return "not a regular file";
  const uint64_t bytes = fs::file_size(file, ec);
  if (ec) return "cannot read file size: " + ec.message();
  if (bytes > maxBytes)
    return "file is larger than the limit (" + std::to_string(bytes) + " bytes)";
  return "";
}

// assimp opens the scene and every file it names (mtllib, .bin buffers, external textures)
// through this: read-only, and only what refusalOf allows.
class LimitedIOSystem : public Assimp::DefaultIOSystem {
 public:
  explicit LimitedIOSystem(uint64_t maxBytes) : maxBytes_(maxBytes) {}
  bool Exists(const char* file) const override { return refusalOf(file, maxBytes_).empty(); }
  Assimp::IOStream* Open(const char* file, const char* mode = "rb") override {
    if (std::strpbrk(mode, "wa+") || !refusalOf(file, maxBytes_).empty()) return nullptr;
    return DefaultIOSystem::Open(file, mode);
  }

 private:
  uint64_t maxBytes_;
};

// ---- reading ----

// assimp's validation messages name its own structures: say what they mean for the file too.
std::string explainAssimpError(const std::string& message) {
  if (message.find("contains no faces") != std::string::npos ||
      message.find("No meshes remaining") != std::string::npos)
    return "scene has no triangles (assimp: " + message + ")";
  if (message.find("mIndices") != std::string::npos &&
      message.find("out of range") != std::string::npos)
    return "a face has a vertex index out of range (assimp: " + message + ")";
  return message;
}

// Sets each mesh's primitive-type flags from its faces. Importers can get them wrong (assimp's
// PLY importer flags a mesh as holding polygons when it holds none), and TriangulateProcess then
// fails an ai_assert, which Debian's assimp 5.2.5 build turns into abort(): a bad file would kill
// the process (fuzz_scene_ply found it).
void setPrimitiveTypesFromFaces(aiScene* scene, const std::string& path) {
  if (scene->mNumMeshes && !scene->mMeshes)
    throw Error(path, "scene lists meshes it does not have");
  for (unsigned i = 0; i < scene->mNumMeshes; ++i) {
    aiMesh* m = scene->mMeshes[i];
    if (!m || (m->mNumFaces && !m->mFaces))
      throw Error(path, "mesh " + std::to_string(i) + " lists faces it does not have");
    unsigned types = 0;
    for (unsigned f = 0; f < m->mNumFaces; ++f) {
      const unsigned n = m->mFaces[f].mNumIndices;
      // TriangulateProcess counts such a face as a triangle and fails the same assertion.
      if (n == 0) throw Error(path, "mesh " + std::to_string(i) + " has a face without vertices");
      types |= n == 1   ? aiPrimitiveType_POINT
               : n == 2 ? aiPrimitiveType_LINE
               : n == 3 ? aiPrimitiveType_TRIANGLE
                        : aiPrimitiveType_POLYGON;
    }
    m->mPrimitiveTypes = types;
  }
}

// The scene `importer` reads from `path`, triangulated, its points and lines removed; it owns
// the scene. Three steps: read, repair the primitive-type flags, validate, then post-process
// (see setPrimitiveTypesFromFaces). The repair comes before the validation because importers
// get the flags wrong in valid files too: assimp's OBJ importer flags a mesh that mixes faces
// with line elements ('l') as triangles only, which the validation refuses.
const aiScene* readScene(Assimp::Importer& importer, const std::string& path,
                         const LoadOptions& options) {
  importer.SetIOHandler(new LimitedIOSystem(options.maxFileBytes));  // the importer owns it
  importer.SetPropertyInteger(AI_CONFIG_PP_SBP_REMOVE,
                              aiPrimitiveType_POINT | aiPrimitiveType_LINE);
  const aiScene* scene = nullptr;
  try {
    scene = importer.ReadFile(path, 0);
    if (scene && scene->mRootNode && !(scene->mFlags & AI_SCENE_FLAGS_INCOMPLETE)) {
      setPrimitiveTypesFromFaces(const_cast<aiScene*>(scene), path);  // the importer owns the scene
      scene = importer.ApplyPostProcessing(aiProcess_ValidateDataStructure);
      if (scene)
        scene = importer.ApplyPostProcessing(aiProcess_Triangulate | aiProcess_SortByPType);
    }
  } catch (const Error&) {
    throw;
  } catch (const std::exception& e) {
    throw Error(path, "cannot load scene: " + explainAssimpError(e.what()));
  }
  if (!scene)
    throw Error(path, "cannot load scene: " + explainAssimpError(importer.GetErrorString()));
  if (!scene->mRootNode || (scene->mFlags & AI_SCENE_FLAGS_INCOMPLETE))
    throw Error(path, "scene is incomplete or has no geometry");
  return scene;
}

// The scene's faces and vertices against the limits, and room for them in `mesh`.
void checkSize(const aiScene* scene, const std::string& path, const LoadOptions& options,
               Mesh& mesh) {
  size_t triangles = 0, vertices = 0;
  for (unsigned i = 0; i < scene->mNumMeshes; ++i) {
    triangles += scene->mMeshes[i]->mNumFaces;
    vertices += scene->mMeshes[i]->mNumVertices;
  }
  if (triangles > options.maxTriangles)
    throw Error(path, "scene has " + std::to_string(triangles) + " faces, more than the limit of " +
                          std::to_string(options.maxTriangles));
  if (vertices > options.maxVertices)
    throw Error(path, "scene has " + std::to_string(vertices) +
                          " vertices, more than the limit of " +
                          std::to_string(options.maxVertices));
  mesh.positions.reserve(vertices);
  mesh.triangles.reserve(triangles);
}

// ---- materials ----

// Converts one assimp material and its texture to ours, loading each texture file once.
class MaterialBuilder {
 public:
  MaterialBuilder(const aiScene* scene, const std::string& path, uint64_t maxFileBytes,
                  bool noTextures, Mesh& mesh, std::vector<std::string>& warnings)
      : scene_(scene),
        path_(path),
        dir_(fs::path(path).parent_path()),
        maxFileBytes_(maxFileBytes),
        noTextures_(noTextures),
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
    if (noTextures_) return mesh_.addMaterial(m);
    if (in->GetTexture(aiTextureType_BASE_COLOR, 0, &texPath) == AI_SUCCESS ||
        in->GetTexture(aiTextureType_DIFFUSE, 0, &texPath) == AI_SUCCESS) {
      m.texture = texture(texPath.C_Str());
      // A texture is modulated by the factor; OBJ files often set Kd to 0 with a map_Kd.
      if (m.texture >= 0 && m.baseColor.maxCoeff() <= 0.0f) m.baseColor.setOnes();
    }
    return mesh_.addMaterial(m);
  }

 private:
  // The index of texture `ref` in the mesh, or -1 (and a warning) when it cannot be read.
  int texture(const std::string& ref) {
    auto it = cache_.find(ref);
    if (it != cache_.end()) return it->second;
    int index = -1;
    try {
      const aiTexture* emb = scene_->GetEmbeddedTexture(ref.c_str());
      Image8 img = emb ? embeddedImage(emb, ref) : fileImage(ref);
      Texture t;
      t.name = ref;
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

  Image8 embeddedImage(const aiTexture* emb, const std::string& ref) const {
    if (emb->mHeight == 0)  // compressed (png/jpg) bytes
      return decodeImage8(emb->pcData, emb->mWidth, path_ + ":" + ref + "." + emb->achFormatHint);
    Image8 img(emb->mWidth, emb->mHeight, 3);  // from raw BGRA texels
    for (size_t i = 0; i < size_t(emb->mWidth) * emb->mHeight; ++i) {
      img.data[3 * i] = emb->pcData[i].r;
      img.data[3 * i + 1] = emb->pcData[i].g;
      img.data[3 * i + 2] = emb->pcData[i].b;
    }
    return img;
  }

  Image8 fileImage(const std::string& ref) const {
    std::string rel = ref;
    for (auto& c : rel)
      if (c == '\\') c = '/';
    const std::string file = (dir_ / rel).string();
    const std::string refusal = refusalOf(file, maxFileBytes_);
    if (!refusal.empty()) throw Error(file, refusal);
    return readImage8(file);
  }

  const aiScene* scene_;
  std::string path_;
  fs::path dir_;
  uint64_t maxFileBytes_;
  bool noTextures_;  // the textures are Basis Universal: base colours only, warned about once
  Mesh& mesh_;
  std::vector<std::string>& warnings_;
  std::map<std::string, int> cache_;
};

// Our material for each of the scene's, or one white material when it has none.
std::vector<int> buildMaterials(const aiScene* scene, const std::string& path,
                                const LoadOptions& options, bool noTextures, Scene& out) {
  MaterialBuilder materials(scene, path, options.maxFileBytes, noTextures, out.mesh, out.warnings);
  std::vector<int> materialMap;
  for (unsigned i = 0; i < scene->mNumMaterials; ++i)
    materialMap.push_back(materials.build(scene->mMaterials[i]));
  if (materialMap.empty()) materialMap.push_back(out.mesh.addMaterial(Material{}));
  return materialMap;
}

// ---- geometry ----

// What appendNode needs besides the node: the same for the whole tree.
struct AppendContext {
  const aiScene* scene;
  const std::string& path;
  const LoadOptions& options;
  const std::vector<int>& materialMap;
  bool linearVertexColors;
};

// Mesh m's vertices, placed by `world`, scaled, with their texture coordinates and linear
// colours (white without).
void appendVertices(const AppendContext& ctx, const aiMesh* m, const aiMatrix4x4& world,
                    Mesh& out) {
  const float scale = static_cast<float>(ctx.options.scale);
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
      if (!ctx.linearVertexColors)
        rgb = Eigen::Vector3f(srgbToLinear(rgb.x()), srgbToLinear(rgb.y()), srgbToLinear(rgb.z()));
      out.colors.push_back(rgb);
    } else {
      out.colors.emplace_back(1.0f, 1.0f, 1.0f);
    }
  }
}

// Mesh m's triangles, their vertices from `base` on.
void appendTriangles(const AppendContext& ctx, const aiMesh* m, int base, Mesh& out) {
  if (m->mMaterialIndex >= ctx.materialMap.size())
    throw Error(ctx.path, "a mesh names material " + std::to_string(m->mMaterialIndex) +
                              ", which the file does not have");
  const int material = ctx.materialMap[m->mMaterialIndex];
  for (unsigned f = 0; f < m->mNumFaces; ++f) {
    const aiFace& face = m->mFaces[f];
    if (face.mNumIndices != 3) continue;  // points and lines left by SortByPType
    out.triangles.emplace_back(base + face.mIndices[0], base + face.mIndices[1],
                               base + face.mIndices[2]);
    out.triangleMaterial.push_back(material);
  }
}

void appendNode(const AppendContext& ctx, const aiNode* node, const aiMatrix4x4& parent,
                Mesh& out) {
  const aiMatrix4x4 world = parent * node->mTransformation;
  for (unsigned k = 0; k < node->mNumMeshes; ++k) {
    const aiMesh* m = ctx.scene->mMeshes[node->mMeshes[k]];
    if (!(m->mPrimitiveTypes & aiPrimitiveType_TRIANGLE)) continue;
    // A mesh referenced by many nodes is instanced once per node: check before growing.
    if (out.triangles.size() + m->mNumFaces > ctx.options.maxTriangles ||
        out.positions.size() + m->mNumVertices > ctx.options.maxVertices)
      throw Error(ctx.path, "scene has more than " + std::to_string(ctx.options.maxTriangles) +
                                " triangles or " + std::to_string(ctx.options.maxVertices) +
                                " vertices (the limits) after instancing");
    const int base = static_cast<int>(out.positions.size());
    appendVertices(ctx, m, world, out);
    appendTriangles(ctx, m, base, out);
  }
  for (unsigned c = 0; c < node->mNumChildren; ++c) appendNode(ctx, node->mChildren[c], world, out);
}

}  // namespace

void importWithAssimp(const std::string& path, const LoadOptions& options, const AssimpImport& how,
                      Scene& out) {
  Assimp::Importer importer;
  const aiScene* scene = readScene(importer, path, options);
  checkSize(scene, path, options, out.mesh);
  const std::vector<int> materialMap = buildMaterials(scene, path, options, how.noTextures, out);
  appendNode(AppendContext{scene, path, options, materialMap, how.linearVertexColors},
             scene->mRootNode, aiMatrix4x4(), out.mesh);
}

}  // namespace paircast
