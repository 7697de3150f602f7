//! YOLO over OpenCV DNN (pending).
