// Checkpoints that Python's torch.load reads, and a loader for ours and the official CroCo
// .pth files. Files from Python's torch.save are zip archives (data.pkl plus one record per
// storage) whose state_dict is a collections.OrderedDict, which LibTorch 1.13's unpickler turns
// into None; so data.pkl is read here by a small pickle reader that only builds values (dicts,
// lists, tuples, numbers, strings, tensors) and never runs code: an unknown class becomes an
// inert placeholder holding its state.
#pragma once

#include <torch/torch.h>

#include <map>
#include <nlohmann/json.hpp>
#include <string>

#include "model/croco_config.h"
#include "model/croco_net.h"

namespace paircast {

struct Checkpoint {
  std::map<std::string, torch::Tensor> model;  // the state_dict
  nlohmann::json args;                         // hyper-parameters, when the file has them as a dict
  bool hasArgs = false;
  int64_t epoch = -1;
  // Other tensor-valued entries (optimizer state etc.), flattened as "optimizer/state/3/exp_avg".
  std::map<std::string, torch::Tensor> extraTensors;
  nlohmann::json extra;  // other scalar entries (step, data position, ...)
};

// What the checkpoint's model was trained on (pretrain --task): "croco" unless it says "mae".
std::string trainedTask(const Checkpoint& checkpoint);

// Writes {'model': state_dict, 'args': {...}, 'epoch': e, ...extra} atomically (temp + rename).
// `extraTensors` keys "a/b" become nested dicts {'a': {'b': tensor}}.
void saveCheckpoint(const std::string& path, CroCoNet& model, int64_t epoch,
                    const nlohmann::json& extra = nlohmann::json::object(),
                    const std::map<std::string, torch::Tensor>& extraTensors = {});

// The same for any module: {'model': state, 'epoch': e, ...entries} (entries hold 'args' or
// 'croco_kwargs' and the rest).
void saveCheckpoint(const std::string& path, const std::map<std::string, torch::Tensor>& state,
                    int64_t epoch, const nlohmann::json& entries,
                    const std::map<std::string, torch::Tensor>& extraTensors = {});

// Writes a dict of tensors {'name': tensor} atomically, without TorchScript's type tags, so that
// Python's torch.load reads it with its defaults (weights_only=True since PyTorch 2.6).
void saveTensors(const std::string& path, const std::map<std::string, torch::Tensor>& tensors);

// Reads our files and official ones (a plain state_dict, or {'model': ...}). Throws
// paircast::Error naming the file (and the key, when one is at fault).
Checkpoint loadCheckpoint(const std::string& path);

// Copies `state` into `model` strictly: every key present, none unexpected, shapes equal.
// The error lists the missing and unexpected keys and the shape mismatches.
void loadStateDictStrict(CroCoNet& model, const std::map<std::string, torch::Tensor>& state,
                         const std::string& source);
void loadStateDictStrict(torch::nn::Module& module,
                         const std::map<std::string, torch::Tensor>& state,
                         const std::string& source);

// The model's state_dict with the official names (a module shared under two names, as the DPT
// head's, appears under both, as in PyTorch's).
std::map<std::string, torch::Tensor> stateDict(CroCoNet& model);
std::map<std::string, torch::Tensor> stateDict(const torch::nn::Module& module);

// The configuration a checkpoint's tensors imply, for files without args: widths, depths,
// patch and image size from the shapes; head counts cannot be read from shapes and come from
// `heads` (enc, dec). Used to check flags against a foreign checkpoint.
void checkConfigAgainstState(const CroCoConfig& config,
                             const std::map<std::string, torch::Tensor>& state,
                             const std::string& source);

// Refuses, naming `source`, a configuration whose CroCo network, plus `headParameters` (a
// downstream head's: DownstreamConfig::headParameters), would hold more than a few times the
// values the checkpoint's own tensors hold: the configuration of an untrusted file sizes the
// model that is built (and filled at random) before its weights are read into it.
void checkModelFitsState(const CroCoConfig& config,
                         const std::map<std::string, torch::Tensor>& state,
                         const std::string& source, int64_t headParameters = 0);

}  // namespace paircast
