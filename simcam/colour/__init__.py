"""Colour science of simcam: DNG camera-colour maths and display transforms (pure functions)."""
