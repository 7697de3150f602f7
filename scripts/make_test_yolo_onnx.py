#!/usr/bin/env python3
"""Builds services/detection/tests/data/tiny_yolov8.onnx, the small ONNX model that
tests the YOLO load-and-decode path (no real model can be downloaded here).

The graph is YOLOv8-shaped: input "images" (1, 3, 64, 64), output "output0"
(1, 4 + 2 classes, 4 candidates). A 32x32 stride-32 convolution turns each quadrant of
the input into one candidate, and a reshape lays the candidates out. Every output is
proportional to the quadrant's brightness: a white quadrant (sum 3072 after the 1/255
scaling) gives the box cx=48, cy=16, w=20, h=10 with class-0 score 0.9; a black one
gives zeros. Class 1 always scores 0.05.

Run: pip install onnx && python3 scripts/make_test_yolo_onnx.py
"""
import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

OUT = "services/detection/tests/data/tiny_yolov8.onnx"
full = 3 * 32 * 32
per_unit = np.array([48.0, 16.0, 20.0, 10.0, 0.9, 0.0], dtype=np.float32) / full
weights = np.repeat(per_unit[:, None, None, None], 3 * 32 * 32).reshape(6, 3, 32, 32)
bias = np.array([0, 0, 0, 0, 0, 0.05], dtype=np.float32)

graph = helper.make_graph(
    [
        helper.make_node("Conv", ["images", "w", "b"], ["grid"], kernel_shape=[32, 32], strides=[32, 32]),
        helper.make_node("Reshape", ["grid", "shape"], ["output0"]),
    ],
    "tiny_yolov8",
    [helper.make_tensor_value_info("images", TensorProto.FLOAT, [1, 3, 64, 64])],
    [helper.make_tensor_value_info("output0", TensorProto.FLOAT, [1, 6, 4])],
    [
        numpy_helper.from_array(weights.astype(np.float32), "w"),
        numpy_helper.from_array(bias, "b"),
        numpy_helper.from_array(np.array([1, 6, 4], dtype=np.int64), "shape"),
    ],
)
model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 11)], producer_name="dualgeo-tests")
model.ir_version = 7
onnx.checker.check_model(model)
onnx.save(model, OUT)
print("wrote", OUT)
