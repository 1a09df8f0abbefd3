"""Pictures of poses with OpenCV: the scene, camera, drawing order and drawing, what can be
drawn (keys, BVH, traces, sessions), contact sheets and videos.
"""
