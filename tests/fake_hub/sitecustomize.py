"""Test-only: with this folder on PYTHONPATH and OMNID_FAKE_HUB_DIR set, Python replaces the two Hub
requests of an upload (create_repo, upload_folder) and card validation by a local folder at start-up, so
LeRobot's own push path runs unchanged up to the network, which tests cannot reach."""

import os
import shutil
from pathlib import Path
from types import SimpleNamespace

_TARGET = os.environ.get("OMNID_FAKE_HUB_DIR")

if _TARGET:
    from huggingface_hub import HfApi, ModelCard

    def _create_repo(self, repo_id, **kwargs):
        return SimpleNamespace(repo_id=repo_id)

    def _upload_folder(self, *, repo_id, folder_path, **kwargs):
        destination = Path(_TARGET) / repo_id
        shutil.copytree(folder_path, destination, dirs_exist_ok=True)
        return SimpleNamespace(repo_url=SimpleNamespace(url=destination.as_uri()), oid="local")

    HfApi.create_repo = _create_repo
    HfApi.upload_folder = _upload_folder
    ModelCard.validate = lambda self, *args, **kwargs: None
