"""Scenes: validated configs (SI units in field names), presets and the loader."""

from scenes.config import SceneConfig
from scenes.loader import ConfigError, config_json, list_presets, load_scene

__all__ = ["ConfigError", "SceneConfig", "config_json", "list_presets", "load_scene"]
