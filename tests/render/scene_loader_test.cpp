#include "render/scene_loader.h"

#include <gtest/gtest.h>

#include <assimp/scene.h>
#include <assimp/Exporter.hpp>
#include <filesystem>
#include <fstream>

#include "render/ray_caster.h"
#include "test_errors.h"
#include "test_paths.h"
#include "util/error.h"
#include "util/image_io.h"

namespace paircast {
namespace {

namespace fs = std::filesystem;

// An in-memory assimp scene: one quad (two triangles, with UVs and vertex colours) under a
// child node translated by (10, 20, 30), with a red base colour.
std::unique_ptr<aiScene> makeAssimpScene() {
  auto scene = std::make_unique<aiScene>();
  scene->mRootNode = new aiNode("root");
  auto* child = new aiNode("child");
  child->mTransformation = aiMatrix4x4(1, 0, 0, 10, 0, 1, 0, 20, 0, 0, 1, 30, 0, 0, 0, 1);
  child->mParent = scene->mRootNode;
  scene->mRootNode->mChildren = new aiNode* [1] { child };
  scene->mRootNode->mNumChildren = 1;
  child->mMeshes = new unsigned[1]{0};
  child->mNumMeshes = 1;

  scene->mMaterials = new aiMaterial*[1];
  scene->mMaterials[0] = new aiMaterial();
  aiColor4D red(0.8f, 0.1f, 0.1f, 1.0f);
  scene->mMaterials[0]->AddProperty(&red, 1, AI_MATKEY_COLOR_DIFFUSE);
  scene->mMaterials[0]->AddProperty(&red, 1, AI_MATKEY_BASE_COLOR);
  aiString name("red");
  scene->mMaterials[0]->AddProperty(&name, AI_MATKEY_NAME);
  scene->mNumMaterials = 1;

  auto* mesh = new aiMesh();
  mesh->mPrimitiveTypes = aiPrimitiveType_TRIANGLE;
  mesh->mNumVertices = 4;
  mesh->mVertices = new aiVector3D[4]{{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  mesh->mNormals = new aiVector3D[4]{{0, 0, 1}, {0, 0, 1}, {0, 0, 1}, {0, 0, 1}};
  mesh->mTextureCoords[0] = new aiVector3D[4]{{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  mesh->mNumUVComponents[0] = 2;
  mesh->mNumFaces = 2;
  mesh->mFaces = new aiFace[2];
  const unsigned tris[2][3] = {{0, 1, 2}, {0, 2, 3}};
  for (int f = 0; f < 2; ++f) {
    mesh->mFaces[f].mNumIndices = 3;
    mesh->mFaces[f].mIndices = new unsigned[3]{tris[f][0], tris[f][1], tris[f][2]};
  }
  mesh->mMaterialIndex = 0;
  scene->mMeshes = new aiMesh* [1] { mesh };
  scene->mNumMeshes = 1;
  return scene;
}

std::string exportScene(const std::string& formatId, const std::string& path) {
  Assimp::Exporter exporter;
  auto scene = makeAssimpScene();
  if (exporter.Export(scene.get(), formatId, path) != AI_SUCCESS)
    ADD_FAILURE() << "assimp could not export " << formatId << ": " << exporter.GetErrorString();
  return path;
}

void expectTranslatedQuad(const Scene& s, const std::string& what, bool hasMaterials = true) {
  SCOPED_TRACE(what);
  ASSERT_EQ(s.mesh.numTriangles(), 2u);
  const MeshStats st = computeStats(s.mesh);
  // The node transform moves the unit quad to (10..11, 20..21, 30).
  EXPECT_NEAR(st.boundsMin.x(), 10.0f, 1e-4f);
  EXPECT_NEAR(st.boundsMax.x(), 11.0f, 1e-4f);
  EXPECT_NEAR(st.boundsMin.y(), 20.0f, 1e-4f);
  EXPECT_NEAR(st.boundsMax.y(), 21.0f, 1e-4f);
  EXPECT_NEAR(st.boundsMin.z(), 30.0f, 1e-4f);
  EXPECT_NEAR(st.boundsMax.z(), 30.0f, 1e-4f);
  ASSERT_FALSE(s.mesh.materials.empty());
  if (!hasMaterials) return;  // PLY has no materials
  const Material& m = s.mesh.materials[s.mesh.triangleMaterial[0]];
  EXPECT_NEAR(m.baseColor.x(), 0.8f, 1e-3f);
  EXPECT_NEAR(m.baseColor.y(), 0.1f, 1e-3f);
}

class SceneFormat : public ::testing::TestWithParam<std::pair<std::string, std::string>> {};

TEST_P(SceneFormat, LoadsWithNodeTransformsAndMaterial) {
  const auto& [formatId, ext] = GetParam();
  const std::string path = exportScene(formatId, testing::scratchDir(formatId) + "/quad." + ext);
  expectTranslatedQuad(loadScene(path), formatId, ext != "ply");
}

INSTANTIATE_TEST_SUITE_P(
    Assimp, SceneFormat,
    ::testing::Values(std::make_pair("glb2", "glb"), std::make_pair("gltf2", "gltf"),
                      std::make_pair("collada", "dae"), std::make_pair("fbxa", "fbx"),
                      std::make_pair("obj", "obj"), std::make_pair("ply", "ply")),
    [](const auto& info) { return info.param.second; });

TEST(SceneLoader, ObjWithMtlAndTexture) {
  const std::string dir = testing::scratchDir("obj");
  Image8 tex(2, 2, 3, 0);
  for (int i = 0; i < 4; ++i) tex.data[3 * i] = 255;  // all red
  fs::create_directories(dir + "/tex");
  writeImage(dir + "/tex/red.png", tex);
  std::ofstream(dir + "/room.mtl") << "newmtl wall\nKd 1 1 1\nmap_Kd tex/red.png\n"
                                      "newmtl plain\nKd 0 0.5 0\n";
  std::ofstream(dir + "/room.obj") << "mtllib room.mtl\n"
                                      "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
                                      "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                                      "usemtl wall\nf 1/1 2/2 3/3 4/4\n"  // a quad: triangulated
                                      "usemtl plain\nf 1 3 4\n";
  const Scene s = loadScene(dir + "/room.obj");
  EXPECT_EQ(s.mesh.numTriangles(), 3u);
  ASSERT_EQ(s.mesh.textures.size(), 1u);
  EXPECT_EQ(s.mesh.textures[0].width, 2);
  const Material& wall = s.mesh.materials[s.mesh.triangleMaterial[0]];
  EXPECT_EQ(wall.texture, 0);
  EXPECT_TRUE(s.mesh.textures[0].sample(0.3f, 0.6f).isApprox(Eigen::Vector3f(1, 0, 0)));
  const Material& plain = s.mesh.materials[s.mesh.triangleMaterial[2]];
  EXPECT_EQ(plain.texture, -1);
  EXPECT_NEAR(plain.baseColor.y(), 0.5f, 1e-6f);
  EXPECT_TRUE(s.warnings.empty());
}

// Sweet Home 3D's catalogues have such files (a fridge, a TV): faces of two vertices among
// the triangles. assimp's OBJ importer flags the mesh as triangles only, and its own validation
// then refused the file.
TEST(SceneLoader, ObjWithTwoVertexFacesAmongItsTrianglesLoadsItsTriangles) {
  const std::string dir = testing::scratchDir("lines");
  std::ofstream(dir + "/lines.obj") << "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\n"
                                       "f 1 2 3\nf 3 5\nf 1 3 4\nf 1 5\n";
  const Scene s = loadScene(dir + "/lines.obj");
  EXPECT_EQ(s.mesh.numTriangles(), 2u);
  EXPECT_TRUE(s.warnings.empty());
}

TEST(SceneLoader, MissingTextureWarnsAndKeepsTheScene) {
  const std::string dir = testing::scratchDir("objnotex");
  std::ofstream(dir + "/a.mtl") << "newmtl m\nKd 1 1 1\nmap_Kd nowhere.png\n";
  std::ofstream(dir + "/a.obj") << "mtllib a.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nusemtl m\nf 1 2 3\n";
  const Scene s = loadScene(dir + "/a.obj");
  EXPECT_EQ(s.mesh.numTriangles(), 1u);
  ASSERT_EQ(s.warnings.size(), 1u);
  EXPECT_NE(s.warnings[0].find("nowhere.png"), std::string::npos);
}

// The smallest IFC file assimp accepts: a project, a site, and one proxy element whose body is
// a faceted B-rep tetrahedron.
const char* kTetrahedronIfc = R"IFC(ISO-10303-21;
HEADER;
FILE_DESCRIPTION(('ViewDefinition [CoordinationView]'),'2;1');
FILE_NAME('box.ifc','2026-01-01T00:00:00',(''),(''),'paircast','paircast','');
FILE_SCHEMA(('IFC2X3'));
ENDSEC;
DATA;
#1=IFCPROJECT('0001',#5,'p',$,$,$,$,(#20),#10);
#5=IFCOWNERHISTORY(#6,#7,$,.ADDED.,$,$,$,0);
#6=IFCPERSONANDORGANIZATION(#8,#9,$);
#7=IFCAPPLICATION(#9,'1','paircast','paircast');
#8=IFCPERSON($,$,'p',$,$,$,$,$);
#9=IFCORGANIZATION($,'o',$,$,$);
#10=IFCUNITASSIGNMENT((#11));
#11=IFCSIUNIT(*,.LENGTHUNIT.,$,.METRE.);
#20=IFCGEOMETRICREPRESENTATIONCONTEXT($,'Model',3,1.0E-5,#21,$);
#21=IFCAXIS2PLACEMENT3D(#22,$,$);
#22=IFCCARTESIANPOINT((0.,0.,0.));
#30=IFCBUILDINGELEMENTPROXY('0002',#5,'box',$,$,#31,#40,$,$);
#31=IFCLOCALPLACEMENT($,#21);
#40=IFCPRODUCTDEFINITIONSHAPE($,$,(#41));
#41=IFCSHAPEREPRESENTATION(#20,'Body','Brep',(#50));
#50=IFCFACETEDBREP(#51);
#51=IFCCLOSEDSHELL((#60,#61,#62,#63));
#101=IFCCARTESIANPOINT((0.,0.,0.));
#102=IFCCARTESIANPOINT((1.,0.,0.));
#103=IFCCARTESIANPOINT((0.,1.,0.));
#104=IFCCARTESIANPOINT((0.,0.,1.));
#60=IFCFACE((#70));
#70=IFCFACEOUTERBOUND(#80,.T.);
#80=IFCPOLYLOOP((#101,#103,#102));
#61=IFCFACE((#71));
#71=IFCFACEOUTERBOUND(#81,.T.);
#81=IFCPOLYLOOP((#101,#102,#104));
#62=IFCFACE((#72));
#72=IFCFACEOUTERBOUND(#82,.T.);
#82=IFCPOLYLOOP((#101,#104,#103));
#63=IFCFACE((#73));
#73=IFCFACEOUTERBOUND(#83,.T.);
#83=IFCPOLYLOOP((#102,#103,#104));
#200=IFCSITE('0003',#5,'site',$,$,#31,$,$,.ELEMENT.,$,$,$,$,$);
#201=IFCRELAGGREGATES('0004',#5,$,$,#1,(#200));
#202=IFCRELCONTAINEDINSPATIALSTRUCTURE('0005',#5,$,$,(#30),#200);
ENDSEC;
END-ISO-10303-21;
)IFC";

TEST(SceneLoader, IfcFacetedBrepLoads) {
  const std::string path = testing::scratchDir("ifc") + "/tetra.ifc";
  std::ofstream(path) << kTetrahedronIfc;
  const Scene s = loadScene(path);
  EXPECT_EQ(s.mesh.numTriangles(), 4u);
  // assimp's IFC importer turns IFC's z-up into y-up: the unit tetrahedron spans 1 m on each axis.
  const MeshStats st = computeStats(s.mesh);
  EXPECT_NEAR((st.boundsMax - st.boundsMin).norm(), std::sqrt(3.0f), 1e-4f);
}

TEST(SceneLoader, PlyVertexColoursAreKept) {
  const std::string dir = testing::scratchDir("ply");
  std::ofstream(dir + "/c.ply") << "ply\nformat ascii 1.0\nelement vertex 3\n"
                                   "property float x\nproperty float y\nproperty float z\n"
                                   "property uchar red\nproperty uchar green\nproperty uchar blue\n"
                                   "element face 1\nproperty list uchar int vertex_indices\n"
                                   "end_header\n0 0 0 255 0 0\n1 0 0 255 0 0\n0 1 0 255 0 0\n"
                                   "3 0 1 2\n";
  const Scene s = loadScene(dir + "/c.ply");
  ASSERT_EQ(s.mesh.numTriangles(), 1u);
  EXPECT_TRUE(s.mesh.colors[0].isApprox(Eigen::Vector3f(1, 0, 0), 1e-5f));
}

TEST(SceneLoader, UpAxisAndScaleOptions) {
  const std::string path = exportScene("glb2", testing::scratchDir("up") + "/q.glb");
  LoadOptions o;
  o.up = UpAxis::Z;
  o.scale = 0.5;
  const Scene s = loadScene(path, o);
  EXPECT_EQ(s.up, UpAxis::Z);
  EXPECT_TRUE(s.upVector().isApprox(Eigen::Vector3f::UnitZ()));
  const MeshStats st = computeStats(s.mesh);
  EXPECT_NEAR(st.boundsMin.x(), 5.0f, 1e-4f);  // positions scaled, never rotated
  EXPECT_NEAR(st.boundsMin.z(), 15.0f, 1e-4f);
  EXPECT_EQ(parseUpAxis("y"), UpAxis::Y);
  EXPECT_EQ(parseUpAxis("z"), UpAxis::Z);
  EXPECT_ERROR_CONTAINS(parseUpAxis("x"), "invalid up axis 'x'");
}

// Bad input: each case gets paircast::Error naming the file, never a crash.
void expectLoadError(const std::string& path, const std::string& fragment,
                     const LoadOptions& o = {}) {
  const std::string what = testing::refusalOf(path, [&] { loadScene(path, o); });
  EXPECT_NE(what.find(fragment), std::string::npos) << what;
}

TEST(SceneLoader, BadInputGetsAClearError) {
  const std::string dir = testing::scratchDir("bad");
  expectLoadError(dir + "/missing.glb", "no such file");
  std::ofstream(dir + "/scene.xyz123") << "hello";
  expectLoadError(dir + "/scene.xyz123", "unsupported");
  std::ofstream(dir + "/corrupt.glb") << std::string("glTF\x02\0\0\0garbage-garbage-garbage", 29);
  expectLoadError(dir + "/corrupt.glb", "cannot load");
  std::ofstream(dir + "/empty.obj") << "# nothing here\nv 0 0 0\n";
  expectLoadError(dir + "/empty.obj", "");
  std::ofstream(dir + "/zero.obj");
  expectLoadError(dir + "/zero.obj", "empty");
  std::ofstream(dir + "/nan.obj") << "v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
  expectLoadError(dir + "/nan.obj", "not finite");
  expectLoadError(dir, "folder");
  // Limits refuse big scenes before they are built.
  std::ofstream(dir + "/two.obj") << "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n";
  LoadOptions small;
  small.maxTriangles = 1;
  expectLoadError(dir + "/two.obj", "limit", small);
  LoadOptions tiny;
  tiny.maxFileBytes = 10;
  expectLoadError(dir + "/two.obj", "limit", tiny);
}

TEST(SceneLoader, SharedHabitatScenesLoadAndSurroundACamera) {
  const std::string dir = testing::sharedScenesDir();
  if (dir.empty()) GTEST_SKIP() << "../shared/scenes not present";
  struct Case {
    std::string file;
    UpAxis up;
    size_t triangles;
    Eigen::Vector3d eye, target;
    double minHit;
  };
  const Case cases[] = {
      // simple_room is z-up: a camera in the room, looking slightly down at the table.
      {"simple_room.glb", UpAxis::Z, 84, {0, -3, 1.5}, {0, 1, 0.8}, 0.3},
      // stage_floor1 is a y-up floor: looking down at it from 1.5 m covers the whole view.
      {"stage_floor1.glb", UpAxis::Y, 2048, {0, 1.5, 0}, {1, -2, 1}, 0.99},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.file);
    LoadOptions o;
    o.up = c.up;
    const Scene s = loadScene(dir + "/" + c.file, o);
    EXPECT_EQ(s.mesh.numTriangles(), c.triangles);
    RayCaster caster(s.mesh);
    Camera cam = Camera::fromHfov(128, 128, 60);
    cam.lookAt(c.eye, c.target, s.upVector().cast<double>());
    Frame f;
    caster.render(cam, RenderOptions{}, f);
    EXPECT_GE(f.validFraction(), c.minHit);
  }
}

}  // namespace
}  // namespace paircast
