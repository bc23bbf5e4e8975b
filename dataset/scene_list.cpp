#include "dataset/scene_list.h"

#include <algorithm>
#include <fstream>
#include <map>
#include <set>

#include "render/scene_loader.h"
#include "shard/shard_format.h"
#include "util/atomic_file.h"
#include "util/error.h"

namespace paircast {
namespace fs = std::filesystem;

std::vector<std::string> sortedFilesUnder(const std::string& dir,
                                          const std::function<bool(const fs::path&)>& keep) {
  std::vector<std::string> found;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(dir, ec);
       it != fs::recursive_directory_iterator(); it.increment(ec))
    if (it->is_regular_file(ec) && keep(it->path())) found.push_back(it->path().string());
  std::sort(found.begin(), found.end());
  return found;
}

std::vector<std::string> expandSceneList(const std::vector<std::string>& args) {
  auto isScene = [](const fs::path& p) {
    const std::string ext = p.extension().string();
    if (ext == ".mtl" || ext == ".png" || ext == ".jpg" || ext == ".jpeg" || ext == ".json" ||
        ext == ".txt" || ext == ".md" || ext == ".bin" || ext == ".exr")
      return false;
    return isSupportedSceneFile(p.string());
  };
  std::vector<std::string> out;
  for (const auto& arg : args) {
    std::error_code ec;
    if (fs::is_directory(arg, ec)) {
      const std::vector<std::string> found = sortedFilesUnder(arg, isScene);
      out.insert(out.end(), found.begin(), found.end());
    } else if (fs::is_regular_file(arg, ec) && fs::path(arg).extension() == ".txt") {
      std::ifstream in(arg);
      std::string line;
      const fs::path base = fs::path(arg).parent_path();
      while (std::getline(in, line)) {
        line.erase(0, line.find_first_not_of(" \t"));
        line.erase(line.find_last_not_of(" \t\r") + 1);
        if (line.empty() || line[0] == '#') continue;
        out.push_back(fs::path(line).is_absolute() ? line : (base / line).string());
      }
    } else if (fs::exists(arg, ec)) {
      out.push_back(arg);
    } else {
      throw Error(arg, "no such scene file, folder or list");
    }
  }
  return out;
}

std::vector<std::string> uniqueSceneNames(const std::vector<std::string>& files) {
  // Datasets that name every scene file alike (Replica's <scene>/mesh.ply, MP3D's
  // <scene>/matterport_mesh/<hash>.obj) are told apart by their folder: a stem that several
  // files share becomes "<folder>_<stem>".
  std::map<std::string, int> stems;
  for (const auto& f : files) stems[fs::path(f).stem().string()]++;
  std::vector<std::string> out;
  std::set<std::string> taken;
  for (const auto& f : files) {
    const fs::path p(f);
    std::string stem = p.stem().string();
    const std::string folder = p.parent_path().filename().string();
    if (stems[stem] > 1 && !folder.empty()) stem = folder + "_" + stem;
    stem = sanitizeName(stem);
    std::string name = stem;
    for (int k = 2; taken.count(name); ++k) name = stem + "_" + std::to_string(k);
    taken.insert(name);
    out.push_back(name);
  }
  return out;
}

}  // namespace paircast
