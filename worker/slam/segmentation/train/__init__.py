"""MSNET training: datasets (YOLO-seg, COCO JSON), copy-paste composites, teacher distillation, the loop."""
