scene corner1, database db/base-corner1.db
distance: symmetric epipolar distance: the larger of the two point-to-epipolar-line distances, px

| pair | config | inliers | ≤ 1 px | ≤ 2 px | ≤ 4 px | median px | on surface | true ≤ 1 px | true ≤ 2 px | true ≤ 4 px |
|---|---|---|---|---|---|---|---|---|---|---|
| view0.png view1.png | 2 | 1244 | 65.4 % | 68.1 % | 68.4 % | 0.33 | 1244 | 62.8 % | 67.7 % | 68.4 % |
| view0.png view2.png | 3 | 619 | 61.2 % | 66.9 % | 71.1 % | 0.47 | 619 | 54.3 % | 61.7 % | 64.6 % |
| view0.png view3.png | 2 | 297 | 60.6 % | 66.7 % | 68.7 % | 0.61 | 297 | 53.5 % | 64.6 % | 66.7 % |
| view0.png view4.png | 2 | 393 | 16.5 % | 30.3 % | 43.8 % | 4.74 | 393 | 0.3 % | 0.3 % | 0.5 % |
| view1.png view2.png | 2 | 954 | 93.0 % | 97.3 % | 98.1 % | 0.17 | 954 | 86.3 % | 95.8 % | 98.0 % |
| view1.png view3.png | 2 | 490 | 82.4 % | 89.0 % | 93.1 % | 0.25 | 490 | 73.5 % | 84.7 % | 87.3 % |
| view1.png view4.png | 2 | 262 | 48.9 % | 51.9 % | 52.3 % | 1.31 | 262 | 43.1 % | 50.4 % | 52.3 % |
| view2.png view3.png | 2 | 1446 | 88.2 % | 92.7 % | 93.8 % | 0.20 | 1446 | 83.3 % | 91.4 % | 92.1 % |
| view2.png view4.png | 3 | 648 | 58.3 % | 63.9 % | 67.1 % | 0.49 | 648 | 52.2 % | 57.3 % | 59.0 % |
| view3.png view4.png | 2 | 1565 | 86.8 % | 93.2 % | 96.7 % | 0.21 | 1565 | 80.0 % | 88.2 % | 90.1 % |
| all pairs |  | 7918 | 74.1 % | 79.5 % | 82.1 % | 0.28 | 7918 | 67.8 % | 75.1 % | 76.7 % |
