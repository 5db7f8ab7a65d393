scene corner1, database verify-corner1.db
distance: symmetric epipolar distance: the larger of the two point-to-epipolar-line distances, px

| pair | config | inliers | ≤ 1 px | ≤ 2 px | ≤ 4 px | median px | on surface | true ≤ 1 px | true ≤ 2 px | true ≤ 4 px |
|---|---|---|---|---|---|---|---|---|---|---|
| view0.png view1.png | 2 | 1107 | 93.4 % | 97.9 % | 98.9 % | 0.18 | 1107 | 89.8 % | 97.3 % | 98.8 % |
| view0.png view2.png | 2 | 470 | 90.4 % | 96.4 % | 97.9 % | 0.26 | 470 | 82.6 % | 94.3 % | 97.7 % |
| view0.png view3.png | 2 | 155 | 88.4 % | 97.4 % | 98.7 % | 0.31 | 155 | 78.1 % | 95.5 % | 98.1 % |
| view0.png view4.png | 2 | 76 | 31.6 % | 39.5 % | 42.1 % | 8.21 | 76 | 27.6 % | 39.5 % | 40.8 % |
| view1.png view2.png | 2 | 868 | 94.5 % | 99.0 % | 99.9 % | 0.17 | 868 | 87.9 % | 97.5 % | 99.8 % |
| view1.png view3.png | 2 | 348 | 89.4 % | 96.6 % | 98.6 % | 0.20 | 348 | 81.9 % | 95.1 % | 98.3 % |
| view1.png view4.png | 2 | 148 | 87.2 % | 93.9 % | 95.9 % | 0.27 | 148 | 77.0 % | 91.9 % | 95.3 % |
| view2.png view3.png | 2 | 1308 | 95.0 % | 99.5 % | 99.7 % | 0.17 | 1308 | 90.2 % | 98.6 % | 99.4 % |
| view2.png view4.png | 6 | 340 | 93.8 % | 99.1 % | 100.0 % | 0.21 | 340 | 89.7 % | 97.4 % | 100.0 % |
| view3.png view4.png | 2 | 1391 | 90.4 % | 96.4 % | 98.0 % | 0.19 | 1391 | 84.9 % | 93.9 % | 96.0 % |
| all pairs |  | 6211 | 91.8 % | 97.1 % | 98.2 % | 0.19 | 6211 | 86.2 % | 95.6 % | 97.6 % |

model: 5/5 images registered, 1147 points
relative rotation error (every pair of images, no alignment): mean 0.019° max 0.032°
after a similarity alignment of the camera centres: centre error mean 0.0032 max 0.0075 (scene units), rotation error mean 0.073° max 0.082°
