scene other1, database verify-other1.db
distance: symmetric epipolar distance: the larger of the two point-to-epipolar-line distances, px

| pair | config | inliers | ≤ 1 px | ≤ 2 px | ≤ 4 px | median px | on surface | true ≤ 1 px | true ≤ 2 px | true ≤ 4 px |
|---|---|---|---|---|---|---|---|---|---|---|
| view0.png view1.png | 6 | 1168 | 96.0 % | 99.6 % | 100.0 % | 0.16 | 1168 | 92.1 % | 99.1 % | 100.0 % |
| view0.png view2.png | 6 | 623 | 94.9 % | 99.2 % | 100.0 % | 0.15 | 623 | 90.7 % | 98.9 % | 100.0 % |
| view0.png view3.png | 6 | 356 | 94.9 % | 99.7 % | 100.0 % | 0.16 | 356 | 90.4 % | 98.9 % | 100.0 % |
| view0.png view4.png | 6 | 239 | 98.3 % | 99.6 % | 100.0 % | 0.12 | 239 | 95.8 % | 99.2 % | 100.0 % |
| view1.png view2.png | 6 | 1025 | 97.0 % | 99.6 % | 100.0 % | 0.12 | 1025 | 93.3 % | 99.0 % | 100.0 % |
| view1.png view3.png | 6 | 467 | 97.0 % | 99.8 % | 100.0 % | 0.14 | 467 | 94.0 % | 99.6 % | 100.0 % |
| view1.png view4.png | 6 | 385 | 96.1 % | 99.5 % | 100.0 % | 0.15 | 385 | 91.7 % | 99.0 % | 100.0 % |
| view2.png view3.png | 6 | 666 | 95.3 % | 99.5 % | 100.0 % | 0.13 | 666 | 92.9 % | 99.1 % | 100.0 % |
| view2.png view4.png | 6 | 630 | 94.8 % | 99.5 % | 100.0 % | 0.14 | 630 | 92.2 % | 99.0 % | 100.0 % |
| view3.png view4.png | 3 | 984 | 73.8 % | 78.3 % | 80.6 % | 0.24 | 984 | 70.4 % | 75.9 % | 77.3 % |
| all pairs |  | 6543 | 92.6 % | 96.3 % | 97.1 % | 0.15 | 6543 | 89.1 % | 95.6 % | 96.6 % |

model: 5/5 images registered, 1286 points
relative rotation error (every pair of images, no alignment): mean 0.027° max 0.049°
after a similarity alignment of the camera centres: centre error mean 0.0053 max 0.0071 (scene units), rotation error mean 0.063° max 0.079°
