// The scene files of a job: --scenes arguments (files, folders, .txt lists) expanded into files,
// and the names that tell them apart in outputs and keys.
#pragma once

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace paircast {

// The regular files under `dir` (recursively) that `keep` accepts, sorted by path.
std::vector<std::string> sortedFilesUnder(
    const std::string& dir, const std::function<bool(const std::filesystem::path&)>& keep);

// Expands the --scenes arguments into scene files, sorted within each folder, in argument order.
// Throws paircast::Error naming an argument that does not exist.
std::vector<std::string> expandSceneList(const std::vector<std::string>& args);

// The name of each scene file in outputs and keys: its sanitised stem, or "<folder>_<stem>" when
// several files share the stem (Replica's mesh.ply), with _2, _3, ... added to later files whose
// name is taken.
std::vector<std::string> uniqueSceneNames(const std::vector<std::string>& files);

}  // namespace paircast
